//! What softvk's crates share in their tests, and only there (a dev-dependency, never
//! published): the validated GPU context of every GPU test, a tiny deterministic generator,
//! jittered meshes, the central-difference gradient check of the f64 twins, temporary folders,
//! and where the test meshes are.

use std::ops::Deref;
use std::path::{Path, PathBuf};

use softvk_gpu::gpu::{Context, ContextOptions};

use softvk_raster::mesh::Mesh;

/// A context for one test. Validation is on unless `SOFTVK_VALIDATION=0`; dropping it fails the
/// test if the validation layer said anything the test did not consume.
pub struct Gpu(Option<Context>);

impl Deref for Gpu {
    type Target = Context;
    fn deref(&self) -> &Context {
        self.0.as_ref().expect("context lives until drop")
    }
}

impl Drop for Gpu {
    fn drop(&mut self) {
        let ctx = self.0.take().expect("dropped once");
        let messages = ctx.take_validation_messages();
        drop(ctx); // destruction itself is validated too
        if !std::thread::panicking() {
            assert!(
                messages.is_empty(),
                "validation layer reported {} message(s):\n{}",
                messages.len(),
                messages.join("\n")
            );
        }
    }
}

/// True when the environment says explicitly that there is no Vulkan device.
pub fn no_gpu() -> bool {
    std::env::var("SOFTVK_NO_GPU").is_ok_and(|v| v == "1")
}

/// The validated context, or `None` (after saying so) when `SOFTVK_NO_GPU=1`. Panics when no
/// device can be created otherwise: a missing device fails GPU tests, it never skips them.
pub fn gpu() -> Option<Gpu> {
    gpu_with(|_| {})
}

/// As [`gpu`], with descriptor sets (`true`) or push descriptors where the device has them
/// (`false`) whatever `SOFTVK_DESCRIPTORS` says.
pub fn gpu_descriptors(sets: bool) -> Option<Gpu> {
    gpu_with(|o| o.descriptor_sets = sets)
}

/// As [`gpu`], with the options from the environment changed by `tweak`.
pub fn gpu_with(tweak: impl FnOnce(&mut ContextOptions)) -> Option<Gpu> {
    if no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return None;
    }
    let mut options = ContextOptions::from_env();
    options.validation = validation_wanted();
    tweak(&mut options);
    let ctx = Context::new(&options).unwrap_or_else(|e| {
        panic!(
            "cannot create a Vulkan context ({e}); set SOFTVK_NO_GPU=1 to skip GPU tests explicitly"
        )
    });
    assert_eq!(ctx.validation_enabled(), options.validation);
    Some(Gpu(Some(ctx)))
}

/// Tests validate unless `SOFTVK_VALIDATION=0` says otherwise.
pub fn validation_wanted() -> bool {
    std::env::var("SOFTVK_VALIDATION").map_or(true, |v| v.trim() != "0")
}

/// A tiny deterministic generator (tests must not depend on a crate's stream).
pub struct Lcg(pub u64);

impl Lcg {
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
}

/// `Mesh::icosphere(subdivisions)` with every coordinate moved by up to ±`jitter`: packed
/// positions (3 per vertex, f64) and faces.
pub fn jittered_icosphere(subdivisions: u32, jitter: f64, seed: u64) -> (Vec<f64>, Vec<[u32; 3]>) {
    let mesh = Mesh::icosphere(subdivisions);
    let mut rng = Lcg(seed);
    let x = mesh
        .positions
        .iter()
        .flatten()
        .map(|&v| f64::from(v) + rng.range(-jitter, jitter))
        .collect();
    (x, mesh.faces)
}

/// Asserts `analytic` is the gradient of `f` at `x` by central differences (step 1e-6):
/// every component within `rel` × the largest analytic component.
pub fn assert_grad_matches_fd(x: &[f64], analytic: &[f64], rel: f64, f: impl Fn(&[f64]) -> f64) {
    assert_eq!(x.len(), analytic.len());
    let h = 1e-6;
    let scale = analytic.iter().fold(0.0f64, |m, g| m.max(g.abs()));
    assert!(scale > 0.0, "a zero gradient checks nothing");
    let mut xs = x.to_vec();
    let mut worst = (0.0, 0);
    for i in 0..x.len() {
        xs[i] = x[i] + h;
        let up = f(&xs);
        xs[i] = x[i] - h;
        let down = f(&xs);
        xs[i] = x[i];
        let err = ((up - down) / (2.0 * h) - analytic[i]).abs();
        if err > worst.0 {
            worst = (err, i);
        }
    }
    assert!(
        worst.0 <= rel * scale,
        "component {}: |fd − analytic| = {:e} > {rel:e} × {scale:e}",
        worst.1,
        worst.0
    );
}

/// A fresh folder under the system's temporary directory, removed when dropped.
pub struct TempDir(pub PathBuf);

impl TempDir {
    /// `tag` must be unique among the tests (they run in parallel).
    pub fn new(tag: &str) -> TempDir {
        let dir = std::env::temp_dir().join(format!("softvk-test-{tag}-{}", std::process::id()));
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

/// Where the tests find the meshes they load: `SOFTVK_ASSETS`, else the repository's `assets/`.
pub fn assets_dir() -> PathBuf {
    std::env::var_os("SOFTVK_ASSETS")
        .filter(|v| !v.is_empty())
        .map_or_else(
            || PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../assets")),
            PathBuf::from,
        )
}
