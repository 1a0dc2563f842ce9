//! Neural-network layers as GPU kernels with f64 CPU twins: what the reconstruction network
//! ([`crate::recon`]) is built from.
