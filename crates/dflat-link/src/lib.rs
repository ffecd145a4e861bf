//! dflat-link
