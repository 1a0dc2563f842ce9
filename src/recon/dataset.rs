//! The NMR/SoftRas single-view reconstruction dataset: its layout, a writer that renders
//! [`shapes`](super::shapes) into it, and a reader.
//!
//! **Files.** Per class (a ShapeNet synset id, e.g. `03001627` for chairs) and split (`train`,
//! `val`, `test`), in one folder:
//! - `<class>_<split>_images.npz`: array `arr_0`, uint8, shape (N, 24, 4, 64, 64): object, view,
//!   channel (R, G, B, A), row (0 at the top), column. SoftRas's loader takes the archive's first
//!   array and reshapes it to (N·24, 4, 64, 64).
//! - `<class>_<split>_voxels.npz`: array `arr_0`, uint8 (0/1), shape (N, 32, 32, 32), in the
//!   index order of [`voxel_center`]. Read back, uint8, bool, int32 (nonzero) and float32/64
//!   (≥ 0.5) all mean occupied.
//!
//! **Views.** View v (0 ≤ v < 24) is SoftRas's `get_points_from_angles(2.732, 30, -15 v)`:
//! [`view_camera`], `look_at` the origin with +y up, perspective with a 15° viewing angle, as
//! SoftRas's reconstruction model renders (`SoftRenderer(image_size=64, camera_mode='look_at',
//! viewing_angle=15)`). softvk's `eye_from_angles` is SoftRas's formula, sign for sign
//! (`eye = (d cos el sin az, d sin el, −d cos el cos az)`, azimuth 0 on −z), so the azimuth
//! passed is −15 v exactly as SoftRas's `datasets.py` passes it: view 1 has its eye at
//! azimuth −15°, i.e. at negative x, the camera turning clockwise seen from above.
//!
//! **Voxels.** SoftRas's evaluation (`examples/recon/models.py`, `evaluate_iou`) voxelizes its
//! predicted mesh with `srf.voxelization(faces * 31/32 + 0.5, 32, False)`, which scales by 32
//! and marks cell `floor(g)` along each axis of the face coordinates in their (x, y, z) order:
//! world coordinate p lands in cell `floor(31 p + 16)`, so cell n has its centre at
//! p = (n − 15.5)/31 (centres from −0.5 to 0.5, spacing 1/31). It then compares
//! `voxels.transpose(0, 2, 1, 3)[:, :, :, ::-1]` with the dataset's voxels: dataset index
//! `[a][b][c]` is the voxelization's `[x = b][y = a][z = 31 − c]`. So the dataset's voxel
//! `[a][b][c]` is centred at world `(x, y, z) = ((b − 15.5)/31, (a − 15.5)/31, (15.5 − c)/31)`
//! ([`voxel_center`]): axis 0 is y (up), axis 1 is x, axis 2 is −z. This writer computes
//! occupancy on that lattice ([`voxel_cube`]: centre 0, half-edge 16/31, 32 cells) and stores it
//! in that order, so a SoftRas evaluation reads our files as it reads NMR's.
//!
//! A voxel is occupied when its centre is inside some part of the object (parity per part,
//! OR over parts). NMR's ground truth (binvox) is conservative: any voxel the surface touches,
//! then filled; ours is up to a voxel thinner on every side, unbiased about the surface.

use std::path::{Path, PathBuf};

use super::npz::{NpyArray, NpyData, Npz, write_npz};
use super::shapes::{Category, Shape, generate};
use crate::camera::{Camera, Projection};
use crate::error::{Error, Result};
use crate::field::Cube;
use crate::field::voxel::Occupancy;
use crate::gpu::Context;
use crate::lighting::Lighting;
use crate::raster::gpu::{Method, Renderer, views_per_scene};
use crate::raster::settings::RasterSettings;
use crate::rng::SplitMix64;

/// Views per object.
pub const VIEWS: usize = 24;
/// Image width and height, pixels.
pub const IMAGE_SIZE: usize = 64;
/// Voxels per axis.
pub const VOXEL_RES: usize = 32;
/// Camera distance from the origin.
pub const DISTANCE: f64 = 2.732;
/// Camera elevation, degrees.
pub const ELEVATION: f64 = 30.0;
/// Azimuth step between views, degrees (view v at −v × this).
pub const AZIMUTH_STEP: f64 = 15.0;
/// Perspective viewing angle, degrees (SoftRas's recon model).
pub const VIEWING_ANGLE: f64 = 15.0;

/// The camera of view `v` (0..24): SoftRas's `get_points_from_angles(2.732, 30, -15 v)`,
/// perspective 15°.
pub fn view_camera(v: usize) -> Camera {
    let mut c = Camera::from_angles(DISTANCE, ELEVATION, -AZIMUTH_STEP * v as f64);
    c.projection = Projection::Perspective {
        viewing_angle_deg: VIEWING_ANGLE,
    };
    c
}

/// The cube whose 32³ cell centres are the dataset's voxel centres: centre 0, half-edge 16/31
/// (centres from −0.5 to 0.5 in steps of 1/31).
pub fn voxel_cube() -> Cube {
    Cube {
        center: [0.0; 3],
        half: 16.0 / 31.0,
    }
}

/// World centre of the dataset's voxel `[a][b][c]` (the order of the `_voxels.npz` arrays):
/// `((b − 15.5)/31, (a − 15.5)/31, (15.5 − c)/31)`. Axis 0 is y, axis 1 is x, axis 2 is −z.
pub fn voxel_center(a: usize, b: usize, c: usize) -> [f64; 3] {
    let f = |n: f64| (n - 15.5) / 31.0;
    [f(b as f64), f(a as f64), -f(c as f64)]
}

/// An occupancy over [`voxel_cube`] (index `i + 32 (j + 32 k)` for x, y, z) in the dataset's
/// order: flat `[a][b][c]` with a = j, b = i, c = 31 − k.
pub fn occupancy_to_nmr(occ: &Occupancy) -> Result<Vec<bool>> {
    let r = VOXEL_RES;
    if occ.res as usize != r || occ.cube != voxel_cube() {
        return Err(Error::Input(format!(
            "an occupancy of {}³ over {:?} is not on the dataset's voxel lattice",
            occ.res, occ.cube
        )));
    }
    let mut out = vec![false; r * r * r];
    for k in 0..r {
        for j in 0..r {
            for i in 0..r {
                out[(j * r + i) * r + (r - 1 - k)] = occ.inside[i + r * (j + r * k)];
            }
        }
    }
    Ok(out)
}

/// A dataset split.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Split {
    /// Training objects.
    Train,
    /// Validation objects.
    Val,
    /// Test objects.
    Test,
}

impl Split {
    /// Every split.
    pub const ALL: [Split; 3] = [Split::Train, Split::Val, Split::Test];

    /// The name in file names: `train`, `val`, `test`.
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Val => "val",
            Split::Test => "test",
        }
    }

    /// The split called `s`.
    pub fn parse(s: &str) -> Result<Split> {
        Split::ALL
            .into_iter()
            .find(|x| x.name() == s)
            .ok_or_else(|| Error::Input(format!("unknown split `{s}`; known: train, val, test")))
    }
}

/// The images file of a class and split.
pub fn images_path(dir: &Path, class_id: &str, split: Split) -> PathBuf {
    dir.join(format!("{class_id}_{}_images.npz", split.name()))
}

/// The voxels file of a class and split.
pub fn voxels_path(dir: &Path, class_id: &str, split: Split) -> PathBuf {
    dir.join(format!("{class_id}_{}_voxels.npz", split.name()))
}

/// What [`write_dataset`] writes.
#[derive(Clone, Debug, PartialEq)]
pub struct DatasetOptions {
    /// Categories, one class each (files named by synset id).
    pub categories: Vec<Category>,
    /// Objects per category in `train`.
    pub train: usize,
    /// Objects per category in `val`.
    pub val: usize,
    /// Objects per category in `test`.
    pub test: usize,
    /// Seed of every object (object `n` of a category and split has its own stream, so
    /// changing one split's count leaves the others' objects as they were).
    pub seed: u64,
    /// Objects rendered together in one batch (24 views each), where their topologies match,
    /// and at most as many as one scene's storage bindings hold (more render in more scenes).
    /// The bytes do not depend on it. On lavapipe one at a time is fastest (a batch's
    /// super-sampled buffers outgrow the caches: 8 at a time took 1.4× as long); a GPU may
    /// prefer more.
    pub batch: usize,
    /// σ of the coverage sigmoid: small, so silhouettes are crisp.
    pub sigma: f64,
    /// Render at 2× and average 2×2 (as NMR's renderings are anti-aliased).
    pub antialias: bool,
}

impl Default for DatasetOptions {
    /// Six categories (airplane, bench, car, chair, lamp, table), 500 / 32 / 32 objects (enough
    /// that a class's test mean is not mostly sampling noise), seed 0, one object a batch,
    /// σ = 1e-5, anti-aliased.
    fn default() -> Self {
        DatasetOptions {
            categories: vec![
                Category::Airplane,
                Category::Bench,
                Category::Car,
                Category::Chair,
                Category::Lamp,
                Category::Table,
            ],
            train: 500,
            val: 32,
            test: 32,
            seed: 0,
            batch: 1,
            sigma: 1e-5,
            antialias: true,
        }
    }
}

impl DatasetOptions {
    /// Objects of `split` per category.
    pub fn count(&self, split: Split) -> usize {
        match split {
            Split::Train => self.train,
            Split::Val => self.val,
            Split::Test => self.test,
        }
    }
}

/// The seed of object `index` of `category` in `split`: a hash of the dataset seed and the three,
/// so each object has its own stream.
pub fn object_seed(seed: u64, category: Category, split: Split, index: usize) -> u64 {
    let class: u64 = category.synset().parse().unwrap_or(0);
    let split_tag = match split {
        Split::Train => 1u64,
        Split::Val => 2,
        Split::Test => 3,
    };
    let mut s = SplitMix64(seed);
    let a = s.next_u64();
    let mut s = SplitMix64(a ^ class.wrapping_mul(0xd6e8_feb8_6659_fd93));
    let b = s.next_u64();
    let mut s = SplitMix64(b ^ split_tag.wrapping_mul(0xa076_1d64_78bd_642f));
    let c = s.next_u64();
    SplitMix64(c ^ (index as u64).wrapping_mul(0xe703_7ed1_a0b4_28db)).next_u64()
}

/// The objects of a category and split, as [`write_dataset`] draws them.
pub fn split_shapes(options: &DatasetOptions, category: Category, split: Split) -> Vec<Shape> {
    (0..options.count(split))
        .map(|n| generate(category, object_seed(options.seed, category, split, n)))
        .collect()
}

/// The raster settings of the dataset's renders: 64², σ from the options, SoftRas defaults
/// otherwise (γ = 1e-4, black background, two-sided).
pub fn raster_settings(options: &DatasetOptions) -> RasterSettings {
    RasterSettings {
        width: IMAGE_SIZE as u32,
        height: IMAGE_SIZE as u32,
        sigma: options.sigma,
        antialias: options.antialias,
        ..RasterSettings::default()
    }
}

/// Renders every shape's 24 views with SoftRas's default lights: uint8 RGBA, flat
/// (N, 24, 4, 64, 64). Shapes of equal topology render together, `batch` at a time (at most as
/// many as one scene's storage bindings hold: [`views_per_scene`]), through
/// [`Renderer::prepare_batch`].
pub fn render_shapes(
    ctx: &Context,
    renderer: &Renderer,
    shapes: &[Shape],
    options: &DatasetOptions,
) -> Result<Vec<u8>> {
    let settings = raster_settings(options);
    let lighting = Lighting::default();
    let meshes: Vec<_> = shapes.iter().map(Shape::mesh).collect::<Result<_>>()?;
    let per_object = VIEWS * 4 * IMAGE_SIZE * IMAGE_SIZE;
    let mut out = vec![0u8; shapes.len() * per_object];
    // Group by topology (faces and vertex count), keeping first-seen order.
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for (n, m) in meshes.iter().enumerate() {
        match groups.iter_mut().find(|g| {
            let first = &meshes[g[0]];
            first.faces == m.faces && first.vertex_count() == m.vertex_count()
        }) {
            Some(g) => g.push(n),
            None => groups.push(vec![n]),
        }
    }
    let cameras: Vec<Camera> = (0..VIEWS).map(view_camera).collect();
    let plane = IMAGE_SIZE * IMAGE_SIZE;
    for group in &groups {
        // At most the objects whose views one scene's storage bindings hold (the images, the
        // pixels' aux and the face setups are one binding each): a larger `batch` renders in
        // more scenes, with the same bytes.
        let faces = meshes[group[0]].face_count() as u64;
        let fits = views_per_scene(ctx, faces, &settings) / VIEWS;
        let batch = options.batch.clamp(1, fits.max(1));
        for chunk in group.chunks(batch) {
            let batch_meshes: Vec<_> = chunk.iter().map(|&n| meshes[n].clone()).collect();
            let views: Vec<(usize, Camera)> = (0..chunk.len())
                .flat_map(|m| cameras.iter().map(move |c| (m, *c)))
                .collect();
            let mut scene =
                renderer.prepare_batch(ctx, &batch_meshes, &views, &lighting, &settings)?;
            renderer.run(ctx, &mut scene, Method::default())?;
            let frames = scene.read_frames(ctx)?;
            for (m, &n) in chunk.iter().enumerate() {
                for v in 0..VIEWS {
                    let image = frames.image(m * VIEWS + v);
                    let base = n * per_object + v * 4 * plane;
                    for (p, px) in image.iter().enumerate() {
                        for (ch, &x) in px.iter().enumerate() {
                            out[base + ch * plane + p] = to_u8(x);
                        }
                    }
                }
            }
        }
    }
    Ok(out)
}

fn to_u8(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Voxelizes every shape on the dataset's lattice, in the dataset's order: flat (N, 32, 32, 32).
pub fn voxelize_shapes(shapes: &[Shape]) -> Result<Vec<bool>> {
    let mut out = Vec::with_capacity(shapes.len() * VOXEL_RES.pow(3));
    for s in shapes {
        out.extend(occupancy_to_nmr(
            &s.voxelize(&voxel_cube(), VOXEL_RES as u32)?,
        )?);
    }
    Ok(out)
}

/// Writes the dataset into `out_dir` (created if missing): for each category and each split with
/// objects, its images and voxels files, each atomically. Calls `progress(category, split,
/// objects)` after each pair of files; it returns `false` to stop there (the files written are
/// whole). Returns the files written, in order. The same options give the same bytes.
pub fn write_dataset(
    ctx: &Context,
    out_dir: &Path,
    options: &DatasetOptions,
    progress: &mut dyn FnMut(Category, Split, usize) -> bool,
) -> Result<Vec<PathBuf>> {
    if options.categories.is_empty() {
        return Err(Error::Input("a dataset needs at least one category".into()));
    }
    if Split::ALL.iter().all(|&s| options.count(s) == 0) {
        return Err(Error::Input(
            "a dataset needs at least one object (train, val and test are all 0)".into(),
        ));
    }
    if !(options.sigma.is_finite() && options.sigma > 0.0) {
        return Err(Error::Input(format!(
            "sigma {} must be finite and > 0",
            options.sigma
        )));
    }
    std::fs::create_dir_all(out_dir).map_err(|source| Error::Io {
        path: out_dir.to_path_buf(),
        source,
    })?;
    let renderer = Renderer::new(ctx)?;
    let mut written = Vec::new();
    let mut seen = Vec::new();
    for &category in &options.categories {
        if seen.contains(&category) {
            continue;
        }
        seen.push(category);
        for split in Split::ALL {
            let n = options.count(split);
            if n == 0 {
                continue;
            }
            let shapes = split_shapes(options, category, split);
            let images = render_shapes(ctx, &renderer, &shapes, options)?;
            let voxels = voxelize_shapes(&shapes)?;
            let images = NpyArray::new(
                vec![n, VIEWS, 4, IMAGE_SIZE, IMAGE_SIZE],
                NpyData::U8(images),
            )?;
            let voxels = NpyArray::new(
                vec![n, VOXEL_RES, VOXEL_RES, VOXEL_RES],
                NpyData::U8(voxels.into_iter().map(u8::from).collect()),
            )?;
            let ip = images_path(out_dir, category.synset(), split);
            let vp = voxels_path(out_dir, category.synset(), split);
            write_npz(&ip, &[("arr_0", &images)], true)?;
            write_npz(&vp, &[("arr_0", &voxels)], true)?;
            written.push(ip);
            written.push(vp);
            if !progress(category, split, n) {
                ctx.check_validation()?;
                return Ok(written);
            }
        }
    }
    ctx.check_validation()?;
    Ok(written)
}

/// One class of a split as read back.
#[derive(Clone, Debug, PartialEq)]
pub struct ClassData {
    /// The class id (the file names' prefix, a synset id).
    pub class_id: String,
    /// The category, when the class id is one softvk generates.
    pub category: Option<Category>,
    /// Objects.
    pub count: usize,
    /// uint8 RGBA, flat (N, 24, 4, 64, 64).
    pub images: Vec<u8>,
    /// Occupancy, flat (N, 32, 32, 32) in [`voxel_center`] order.
    pub voxels: Vec<bool>,
}

impl ClassData {
    /// View `v` of object `n`: 4 planes (R, G, B, A) of 64 × 64, row 0 at the top.
    pub fn image(&self, n: usize, v: usize) -> &[u8] {
        let size = 4 * IMAGE_SIZE * IMAGE_SIZE;
        let start = (n * VIEWS + v) * size;
        &self.images[start..start + size]
    }

    /// The 32³ voxels of object `n`, index `(a * 32 + b) * 32 + c` ([`voxel_center`]).
    pub fn voxels_of(&self, n: usize) -> &[bool] {
        let size = VOXEL_RES.pow(3);
        &self.voxels[n * size..(n + 1) * size]
    }
}

/// One split of a dataset folder: every class that has an images file for it.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// The split read.
    pub split: Split,
    /// Classes in class-id order.
    pub classes: Vec<ClassData>,
}

impl Dataset {
    /// Reads every `<class>_<split>_images.npz` of `dir` and its `<class>_<split>_voxels.npz`,
    /// each archive's first array, checking shapes: images uint8 (N, 24, 4, 64, 64) (or
    /// (N·24, 4, 64, 64), as SoftRas reshapes them), voxels (N, 32, 32, 32) of the same N.
    pub fn open(dir: &Path, split: Split) -> Result<Dataset> {
        let suffix = format!("_{}_images.npz", split.name());
        let entries = std::fs::read_dir(dir).map_err(|source| Error::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let mut ids = Vec::new();
        for e in entries {
            let e = e.map_err(|source| Error::Io {
                path: dir.to_path_buf(),
                source,
            })?;
            if let Some(id) = e.file_name().to_str().and_then(|n| n.strip_suffix(&suffix))
                && !id.is_empty()
            {
                ids.push(id.to_owned());
            }
        }
        ids.sort();
        if ids.is_empty() {
            return Err(Error::Input(format!(
                "{}: no *{suffix} file: not a dataset folder for split `{}`",
                dir.display(),
                split.name()
            )));
        }
        let classes = ids
            .into_iter()
            .map(|id| read_class(dir, &id, split))
            .collect::<Result<_>>()?;
        Ok(Dataset { split, classes })
    }
}

fn read_class(dir: &Path, id: &str, split: Split) -> Result<ClassData> {
    let ip = images_path(dir, id, split);
    let vp = voxels_path(dir, id, split);
    let images = Npz::open(&ip)?.first()?;
    let s = IMAGE_SIZE;
    let bad = |p: &Path, why: String| Error::Input(format!("{}: {why}", p.display()));
    let count = match images.shape.as_slice() {
        &[n, VIEWS, 4, h, w] if h == s && w == s => n,
        &[m, 4, h, w] if h == s && w == s && m % VIEWS == 0 => m / VIEWS,
        other => {
            return Err(bad(
                &ip,
                format!(
                    "images of shape {other:?}; expected (N, {VIEWS}, 4, {s}, {s}) or \
                     (N·{VIEWS}, 4, {s}, {s})"
                ),
            ));
        }
    };
    let NpyData::U8(pixels) = images.data else {
        return Err(bad(
            &ip,
            format!(
                "images of dtype {}; expected uint8",
                images.data.dtype_name()
            ),
        ));
    };
    if !vp.exists() {
        return Err(bad(
            &vp,
            "missing: every images file needs its voxels file".into(),
        ));
    }
    let voxels = Npz::open(&vp)?.first()?;
    let r = VOXEL_RES;
    match voxels.shape.as_slice() {
        &[n, a, b, c] if a == r && b == r && c == r => {
            if n != count {
                return Err(bad(
                    &vp,
                    format!(
                        "{n} objects, but {} holds {count}",
                        ip.file_name().unwrap_or_default().to_string_lossy()
                    ),
                ));
            }
        }
        other => {
            return Err(bad(
                &vp,
                format!("voxels of shape {other:?}; expected (N, {r}, {r}, {r})"),
            ));
        }
    }
    Ok(ClassData {
        class_id: id.to_owned(),
        category: Category::from_synset(id),
        count,
        images: pixels,
        voxels: voxels.to_bools(),
    })
}
