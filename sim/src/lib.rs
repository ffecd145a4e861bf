//! dflat-sim
