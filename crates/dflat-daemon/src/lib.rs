//! dflat-daemon
