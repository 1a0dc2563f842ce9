//! Shared test support: a validated GPU context that fails the test on any validation message.
#![allow(dead_code)] // each test binary uses a different subset

pub mod hard;
pub mod host;
pub mod recon;

use softvk::gpu::KernelSpec;

// The validated context lives in softvk-testing, which the crates' unit tests share; each test
// binary uses a different subset.
#[allow(unused_imports)]
pub use softvk_testing::{Gpu, gpu, gpu_descriptors, gpu_with, no_gpu, validation_wanted};

/// Largest |a − b| relative to the largest |b| of a family of 3-vectors, and that largest |b|.
pub fn rel_err3(a: &[[f64; 3]], b: &[[f64; 3]]) -> (f64, f64) {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    let err = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    (err / scale.max(1e-30), scale)
}

/// Each component of `a` against its reference in `b`, held to `rel` of itself plus `floor`
/// (absolute: the measured error of components near zero): the largest share of its bound any
/// component uses (at most 1 passes) and that component's index.
pub fn worst_share(a: &[f64], b: &[f64], rel: f64, floor: f64) -> (f64, usize) {
    assert_eq!(a.len(), b.len());
    assert!(rel > 0.0 && floor > 0.0);
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs() / (rel * y.abs() + floor))
        .enumerate()
        .fold(
            (0.0, 0),
            |w, (i, s)| if s > w.0 || s.is_nan() { (s, i) } else { w },
        )
}

/// What [`worst_share`]'s bounds are measured from: the largest |a − b| over components whose
/// |b| is below `cut` (the floor near zero) and the largest |a − b| / |b| over the others.
pub fn measured(a: &[f64], b: &[f64], cut: f64) -> (f64, f64) {
    a.iter().zip(b).fold((0.0, 0.0), |(near, rel), (x, y)| {
        let e = (x - y).abs();
        if y.abs() < cut {
            (f64::max(near, e), rel)
        } else {
            (near, f64::max(rel, e / y.abs()))
        }
    })
}

/// `SOFTVK_VALIDATION` for a `softvk` process a test starts: the test's own choice
/// ([`validation_wanted`]).
pub fn validation_env() -> &'static str {
    if validation_wanted() { "1" } else { "0" }
}

/// A seeded generator for test data, the same on every platform.
pub fn rng(seed: u64) -> rand_pcg::Pcg64 {
    rand::SeedableRng::seed_from_u64(seed)
}

/// The `softvk` binary of this build, as a command (validation as the binary defaults: pass
/// `SOFTVK_VALIDATION` to change it).
pub fn softvk() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_softvk"))
}

/// A fresh folder for one test's files, removed when dropped. `tag` must be unique among the
/// tests of one test binary (binaries differ by process id).
pub struct TempDir(pub std::path::PathBuf);

impl TempDir {
    /// Creates (or empties) the folder.
    pub fn new(tag: &str) -> TempDir {
        let dir = std::env::temp_dir().join(format!("softvk-test-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }

    /// `name` inside the folder.
    pub fn path(&self, name: &str) -> std::path::PathBuf {
        self.0.join(name)
    }

    /// Writes `text` to `name` inside the folder and returns its path.
    pub fn write(&self, name: &str, text: &str) -> std::path::PathBuf {
        let p = self.path(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    /// Every entry, hidden temporaries included, sorted.
    pub fn entries(&self) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(&self.0)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Three views (elevation 30°, azimuths 0°, 120°, 240°) of a centred disc of radius 0.35 of
/// a `size`² image: the silhouettes (`sil/`) and cameras (`cameras.csv`) of a tiny fit, written
/// into `dir` by the library's own writers. Returns their paths.
pub fn write_disc_inputs(dir: &TempDir, size: u32) -> (std::path::PathBuf, std::path::PathBuf) {
    use softvk::io;
    let sil = dir.path("sil");
    io::write_silhouettes(
        &sil,
        &io::silhouette_names(3),
        size,
        size,
        &disc_masks(size),
    )
    .unwrap();
    let cams = dir.path("cameras.csv");
    io::write_cameras(&cams, &disc_camera_rows()).unwrap();
    (sil, cams)
}

/// The masks of [`write_disc_inputs`], view-major.
pub fn disc_masks(size: u32) -> Vec<f32> {
    let c = (size as f32 - 1.0) / 2.0;
    let r2 = (0.35 * size as f32).powi(2);
    let disc: Vec<f32> = (0..size * size)
        .map(|i| {
            let (x, y) = ((i % size) as f32 - c, (i / size) as f32 - c);
            f32::from(u8::from(x * x + y * y < r2))
        })
        .collect();
    (0..3).flat_map(|_| disc.iter().copied()).collect()
}

/// The cameras of [`write_disc_inputs`].
pub fn disc_camera_rows() -> Vec<softvk::io::CameraRow> {
    (0..3)
        .map(|i| softvk::io::CameraRow {
            distance: 2.732,
            elevation: 30.0,
            azimuth: 120.0 * f64::from(i),
        })
        .collect()
}

/// Every kernel of every crate: softvk-gpu's, softvk-raster's, softvk-fit's, softvk-field's and
/// softvk's own.
pub fn all_kernels() -> impl Iterator<Item = &'static KernelSpec> {
    softvk::gpu::specs::ALL
        .iter()
        .chain(softvk::raster::specs::ALL)
        .chain(softvk_fit::specs::ALL)
        .chain(softvk_field::specs::ALL)
        .chain(softvk::specs::ALL)
        .copied()
}
