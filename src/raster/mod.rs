//! Soft rasterization (SPEC §2), stage by stage: the f64 CPU twin
//! ([`reference`](mod@reference)), and on the GPU the face setup ([`setup`]) and the brute-force
//! fine pass ([`brute`]), driven by [`gpu`]. The tiled forward (binning → tiled fine pass) comes
//! next and is tested against the brute one, bit for bit.

pub mod brute;
pub mod gpu;
pub mod reference;
pub mod setup;
