//! Soft rasterization (SPEC §2–§3), stage by stage: the render settings ([`settings`]), read
//! by everything below; the f64 CPU twins of the forward
//! ([`reference`](mod@reference)) and of the backward ([`reference_grad`]), and on the GPU the
//! face setup ([`setup`]), binning ([`crate::primitives::binning`]) and the fine passes — tiled
//! ([`fine`]) and the brute-force baseline ([`brute`]), bit for bit the same — driven by
//! [`gpu`].

pub mod backward;
pub mod brute;
pub mod fine;
pub mod gpu;
pub mod light;
pub(crate) mod loops;
pub mod reference;
pub mod reference_grad;
pub mod scene;
pub mod settings;
pub mod setup;
