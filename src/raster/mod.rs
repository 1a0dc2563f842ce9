//! Soft rasterization (SPEC §2), stage by stage: the f64 CPU twin
//! ([`reference`](mod@reference)), and on the GPU the face setup ([`setup`]), binning
//! ([`crate::primitives::binning`]) and the fine passes — tiled ([`fine`]) and the brute-force
//! baseline ([`brute`]), bit for bit the same — driven by [`gpu`].

pub mod brute;
pub mod fine;
pub mod gpu;
pub mod reference;
pub mod setup;
