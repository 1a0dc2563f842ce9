//! Soft rasterization (SPEC §2), stage by stage: the f64 CPU twin
//! ([`reference`](mod@reference)) and, on the GPU, the face setup ([`setup`]). The fine passes
//! (brute force, then tiled) follow and are tested against the twin.

pub mod reference;
pub mod setup;
