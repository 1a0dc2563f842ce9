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

/// Test helpers shared with `report`'s tests.
#[cfg(test)]
pub(crate) mod test_support {
    use std::path::{Path, PathBuf};

    /// A fresh folder under the system's temporary directory, removed when dropped.
    pub struct TempDir(pub PathBuf);

    impl TempDir {
        /// `tag` must be unique among the tests (they run in parallel).
        pub fn new(tag: &str) -> TempDir {
            let dir = std::env::temp_dir().join(format!("softvk-fit-{tag}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            TempDir(dir)
        }

        /// `name` inside the folder.
        pub fn path(&self, name: &str) -> PathBuf {
            self.0.join(name)
        }

        /// The folder's entries, sorted (hidden temporary files included).
        pub fn entries(&self) -> Vec<String> {
            entries(&self.0)
        }
    }

    /// The entries of `dir`, sorted.
    pub fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}
