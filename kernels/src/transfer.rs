//! P2G and G2P block kernels.
