//! Soft rasterization (SPEC §2–§3), stage by stage: the f64 CPU twins of the forward
//! ([`reference`](mod@reference)) and of the backward ([`reference_grad`]), and on the GPU the
//! face setup ([`setup`]) and the brute-force fine pass ([`brute`]), driven by [`gpu`]. The tiled
//! forward (binning → tiled fine pass) comes next and is tested against the brute one, bit for
//! bit.

pub mod brute;
pub mod gpu;
pub mod reference;
pub mod reference_grad;
pub mod setup;
