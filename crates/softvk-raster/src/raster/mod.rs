//! Soft rasterization (SPEC §2–§3), stage by stage: the render settings ([`settings`]), read
//! by everything below; the f64 CPU twins of the forward
//! ([`reference`](mod@reference)) and of the backward ([`reference_grad`]), and on the GPU the
//! face setup ([`setup`]), binning ([`crate::primitives::binning`]), the fine passes — tiled
//! ([`fine`]) and the brute-force baseline ([`brute`]), bit for bit the same — and the backward
//! ([`backward`]), driven by [`gpu`]. Beside it, PyTorch3D's rasterizer ([`fragments`]): the K
//! nearest faces of every pixel on the same binning, forward and backward, with its own twin.
//!
//! The layers, none importing from one above it: the settings; the state every stage reads —
//! the [`method`], the [`scene`], what a forward leaves for its backward ([`binned`]) and the
//! kernels' loop counts; the stages; the driver [`gpu`],
//! which re-exports the state its callers name.

pub mod backward;
pub mod binned;
pub mod bits;
pub mod brute;
pub mod fine;
pub mod fragments;
pub mod gpu;
pub mod hard;
pub mod light;
pub(crate) mod loops;
pub mod method;
pub mod reference;
pub mod reference_grad;
pub mod scene;
pub mod settings;
pub mod setup;

/// The rasterizers' kernels (`kernels/raster/raster/`), as `softvk-build` compiled them: a
/// [`KernelSpec`](crate::gpu::KernelSpec) and a bindings struct each, and [`ALL`](specs::ALL).
#[allow(missing_docs)]
pub mod specs {
    use softvk_gpu::gpu::{BindingKind, BindingSpec, BufferRange, KernelSpec};
    include!(concat!(env!("OUT_DIR"), "/kernels.rs"));
}
