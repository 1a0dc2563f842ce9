//! Single-view mesh reconstruction learned from silhouettes (SoftRas §4.2, "3D unsupervised
//! learning"): the NMR/SoftRas dataset format and a procedural dataset in it, and (to come) the
//! encoder–decoder trained through the soft rasterizer.

pub mod batch;
pub mod decode;
pub mod eval;
pub mod train;

pub use decode::{MeshDecoder, view_rotation};
