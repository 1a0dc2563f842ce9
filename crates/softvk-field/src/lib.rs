//! softvk-field: implicit fields learned from silhouettes by sphere probing (Liu et al.,
//! NeurIPS 2019), on Vulkan compute, over softvk-fit's fitting session.
//!
//! The modules, bottom up (none imports from one below it in this list):
//!
//! - [`field`]: implicit fields φ = sigmoid(f) in a bounding cube (dense grid, MLP with
//!   positional encoding, analytic shapes) with a deterministic GPU backward and f64 twins,
//!   marching cubes, occupancy / visual hull / IoU tools and a ray-marched preview.
//! - [`probe`]: sphere probing: sampling (rays, anchors, surface candidates), probing anchors
//!   binned to screen tiles, the silhouette loss and the geometric regularizer, with their
//!   gradients with respect to φ.
//! - [`field_fit`]: a field fitted to silhouettes on softvk-fit's driver and session (the top
//!   crate, softvk, re-exports it as `softvk::fit::field_fit`).
//!
//! The kernels are `kernels/field/` of the repository, listed in [`specs`].

#![warn(missing_docs)]

// The crates below, by the paths the code of this crate names them with (`crate::gpu::…`).
use softvk_fit::{fit, io, rng};
use softvk_gpu::{error, gpu, primitives};
use softvk_raster::{camera, mesh};

pub mod field;
pub mod field_fit;
pub mod probe;

/// This crate's kernels (`kernels/field/`: field evaluation and backward, marching cubes,
/// sampling and probing), as `softvk-build` compiled them.
#[allow(missing_docs)]
pub mod specs {
    use softvk_gpu::gpu::{BindingKind, BindingSpec, BufferRange, KernelSpec};
    include!(concat!(env!("OUT_DIR"), "/kernels.rs"));
}
