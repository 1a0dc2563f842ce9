//! The files of the fitting commands (SPEC §6): the target silhouettes (`--silhouettes DIR`), the
//! views they were taken from (`--cameras C.csv`), and the fitted mesh (`--out M.obj`).
//!
//! Every loader checks its input whole and fails with one [`Error::Input`] line naming the file
//! and what is wrong with it; every writer is atomic (a temporary file beside the target, renamed
//! into place), so a failed run leaves no half-written file and no temporary one.
//!
//! The writers are the loaders' inverses: `write_silhouettes` → `load_silhouettes` and
//! `write_cameras` → `load_cameras` give back what was written, and `write_obj` →
//! [`Mesh::load_obj`](crate::mesh::Mesh::load_obj) the same positions bit for bit.

mod cameras;
mod obj;
mod silhouettes;

#[cfg(test)]
mod tests;

pub use cameras::{CAMERAS_HEADER, CameraRow, check_counts, load_cameras, write_cameras};
pub use obj::{write_obj, write_obj_colored};
pub use silhouettes::{Silhouettes, load_silhouettes, silhouette_names, write_silhouettes};

use std::path::Path;

pub(crate) use crate::atomic_file::AtomicFile;
use crate::error::{Error, Result};

/// One float to one 8-bit channel: clamp to [0, 1], scale by 255, round (NaN gives 0).
pub(crate) fn unit_to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// PNG bytes of `pixels` (8-bit, `color`'s layout); the error names `path`.
pub(crate) fn encode_png(
    pixels: &[u8],
    width: u32,
    height: u32,
    color: image::ExtendedColorType,
    path: &Path,
) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(pixels, width, height, color)
        .map_err(|e| Error::Input(format!("cannot encode PNG {}: {e}", path.display())))?;
    Ok(out)
}

/// Test helpers shared with `report`'s tests (softvk-testing).
#[cfg(test)]
pub(crate) use softvk_testing as test_support;
