//! softvk: differentiable rendering as Vulkan compute kernels.
//!
//! This crate is the top of softvk's workspace: the command line and `softvk bench`, and the
//! layers that fit and learn through the rasterizers. It re-exports the crates below it, so one
//! dependency gives everything under the paths the project itself uses:
//!
//! - softvk-gpu: [`error`] (the one error enum), [`atomic_file`], [`gpu`] (the Vulkan compute
//!   core: contexts owned or adopted with [`gpu::Context::from_raw`], buffers, kernels,
//!   recording into a caller's command buffer), [`fmath`] (correctly rounded maths, the same
//!   bits on every device) and [`primitives`] (scan, sort, sums, tiled binning);
//! - softvk-raster: [`mesh`], [`camera`], [`lighting`] and [`raster`] (the soft rasterizer,
//!   PyTorch3D's fragments, the hard rasterizer, with their twins).
//!
//! An engine that only renders depends on softvk-raster alone. The modules of this crate, bottom
//! up (none imports from one below it in this list):
//!
//! - Inputs: [`assets`] (the meshes found through `SOFTVK_ASSETS` or the checkout), [`io`]
//!   (silhouettes, cameras CSV), [`exr_io`].
//! - [`fit`]: the fitting building blocks as kernels — silhouette losses, Laplacian and flatten
//!   regularizers, deformation, Adam, blur — the loop driver that every fit runs on
//!   ([`fit::driver`]) and the session around it ([`fit::session`]: log, hooks, checkpoints,
//!   resume, stopping rule), the fits (mesh, field, rigid pose, articulated pose), their
//!   checkpoint format and reports.
//! - [`probe`]: implicit-field sphere probing — sampling (rays, anchors, surface candidates),
//!   probing anchors binned to screen tiles, the silhouette loss and the geometric regularizer,
//!   with their gradients with respect to φ.
//! - [`field`]: implicit fields φ = sigmoid(f) in a bounding cube (dense grid, MLP with positional
//!   encoding, analytic shapes) with a deterministic GPU backward, marching cubes, occupancy /
//!   visual hull / IoU tools and a ray-marched preview.
//! - [`nn`]: neural-network layers (Conv2d, Linear, fused activations) as kernels with a
//!   deterministic backward and f64 twins, chained by [`nn::Sequential`].
//! - [`recon`]: single-view reconstruction learned from silhouettes (SoftRas's unsupervised 3D
//!   learning): the NMR dataset format and a procedural dataset in it, the mesh network and the
//!   conditioned implicit field trained on the GPU, evaluation by 3D IoU beside retrieval and
//!   mean-shape baselines.
//! - [`mod@bench`] (feature `bench`): the scene benchmarks behind `softvk bench` — forward and
//!   backward per scene and method, and one iteration of each fit and of reconstruction
//!   training (JSON records).
//!
//! Every kernel has a CPU twin that tests compare it with.

#![warn(missing_docs)]

pub use softvk_gpu::{Error, LimitKind, Result, atomic_file, error, fmath, gpu, primitives};
pub use softvk_raster::{camera, lighting, mesh, raster};

pub mod assets;
#[cfg(feature = "bench")]
pub mod bench;
pub mod exr_io;
pub mod field;
pub mod fit;
pub mod io;
pub mod nn;
pub mod probe;
pub mod recon;
mod rng;

/// This crate's kernels (`kernels/softvk/`: fits, fields and probing, networks,
/// reconstruction), as `softvk-build` compiled them. The crates below list theirs in
/// [`gpu::specs`] and [`raster::specs`].
#[allow(missing_docs)]
pub mod specs {
    use softvk_gpu::gpu::{BindingKind, BindingSpec, BufferRange, KernelSpec};
    include!(concat!(env!("OUT_DIR"), "/kernels.rs"));
}
