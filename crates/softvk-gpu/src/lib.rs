//! softvk-gpu: the Vulkan compute core of softvk, and the bottom of its crates.
//!
//! The modules, bottom up (none imports from one below it in this list):
//!
//! - `text` (user text in one-line messages, public as [`error::one_line`]), [`error`] (the one
//!   error enum of every softvk crate, with the errors of the layers above it: a crate below
//!   cannot wrap a type of a crate above) and [`atomic_file`] (files written whole or not at
//!   all).
//! - [`gpu`]: a [`gpu::Context`] (owned headless, or adopted from a host engine with
//!   [`gpu::Context::from_raw`]), buffers, kernels compiled at build time and the pipeline cache,
//!   and a [`gpu::Recorder`] that records dispatches into a command buffer the caller owns, with
//!   the iteration gate.
//! - [`fmath`]: softvk's own `exp`, `log`, division, `sqrt`, `sin`, `cos`, ... built from
//!   correctly rounded operations, which every kernel uses (`kernels/gpu/include/fmath.glsl`), so
//!   a kernel's bits are the same on every conformant device; the CPU twin is bit-exact.
//! - [`primitives`]: exclusive scan, stable radix sort, sums and tiled binning (which items each
//!   screen tile must visit, exactly), with their CPU twins.
//!
//! The crates above compile their own kernels with `softvk-build` and include this crate's GLSL
//! headers (`common.glsl`, `fmath.glsl`, `binning.glsl`, `fit_reduce.glsl`): its build exports
//! their folder to theirs (`links = "softvk_gpu"`).
//!
//! Every kernel has a CPU twin that tests compare it with.

#![warn(missing_docs)]

// The generated kernel bindings name this crate by its path, as they do in every crate.
extern crate self as softvk_gpu;

pub mod atomic_file;
pub mod error;
pub mod fmath;
pub mod gpu;
pub mod primitives;
mod text;

pub use error::{Error, LimitKind, Result};
