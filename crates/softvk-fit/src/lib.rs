//! softvk-fit: fitting meshes and poses to images through softvk's rasterizers, on Vulkan
//! compute (softvk-raster over softvk-gpu).
//!
//! The modules, bottom up (none imports from one below it in this list):
//!
//! - [`rng`]: the seeded stream every seeded initialization of softvk draws from.
//! - [`io`]: the fitting commands' files (CPU): target silhouettes, the cameras CSV, the fitted
//!   OBJ, all checked on load and written atomically.
//! - [`fit`]: SoftRas's losses, regularizers, deformation and Adam as kernels with f64 twins;
//!   the loop every fit runs on ([`fit::driver`]) and the session around it ([`fit::session`]:
//!   the log whose row names its columns, hooks, checkpoints in one format, resume, the stopping
//!   rule); the mesh, rigid-pose and articulated fits; and (feature `plots`) their reports.
//!
//! The field fit, which needs the fields and sphere probing, is softvk-field's; the crate above
//! both, softvk, re-exports it as `softvk::fit::field_fit`. The kernels are `kernels/fit/` of the
//! repository, listed in [`specs`].

#![warn(missing_docs)]

// The crates below, by the paths the code of this crate names them with (`crate::gpu::…`).
use softvk_gpu::{atomic_file, error, gpu, primitives};
use softvk_raster::{camera, lighting, mesh, raster};

pub mod fit;
pub mod io;
pub mod rng;

/// This crate's kernels (`kernels/fit/`: losses, regularizers, deformation, Adam, blur, pose and
/// skinning), as `softvk-build` compiled them.
#[allow(missing_docs)]
pub mod specs {
    use softvk_gpu::gpu::{BindingKind, BindingSpec, BufferRange, KernelSpec};
    include!(concat!(env!("OUT_DIR"), "/kernels.rs"));
}
