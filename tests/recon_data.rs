//! The NMR/SoftRas dataset side of reconstruction: `.npy`/`.npz` against files
//! NumPy wrote (`tests/data/npz/make_fixtures.py`), the procedural shapes, and the dataset's
//! images, voxels and conventions.
mod common;

use std::path::{Path, PathBuf};

use common::TempDir;
use glam::DVec3;
use softvk::Error;
use softvk::camera::{Camera, Projection};
use softvk::field::voxel::occupancy_from_fn;
use softvk::raster::gpu::Renderer;
use softvk::recon::dataset::{
    self, Dataset, DatasetOptions, IMAGE_SIZE, Split, VIEWS, VOXEL_RES, voxel_center,
};
use softvk::recon::eval;
use softvk::recon::npz::{self, NpyArray, NpyData, Npz};
use softvk::recon::shapes::{Category, MIN_THICKNESS, Part, generate};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/npz")
        .join(name)
}

/// The message of an `Error::Input`, failing the test on any other outcome.
fn input_error<T: std::fmt::Debug>(r: softvk::Result<T>) -> String {
    match r {
        Err(Error::Input(m)) => m,
        other => panic!("expected Error::Input, got {other:?}"),
    }
}

#[test]
fn numpy_written_arrays_read_with_their_shapes_dtypes_and_values() {
    let images: Vec<u8> = (0..2 * 3 * 4 * 5 * 6).map(|n| (n % 251) as u8).collect();
    for name in ["images_u8.npz", "images_u8_compressed.npz"] {
        let a = npz::read_npz_first(&fixture(name)).unwrap();
        assert_eq!(a.shape, [2, 3, 4, 5, 6], "{name}");
        assert_eq!(a.data, NpyData::U8(images.clone()), "{name}");
    }
    let occupied: Vec<bool> = (0..2 * 8 * 8 * 8).map(|n| (n * 7) % 3 == 0).collect();
    let half: Vec<bool> = (0..2 * 8 * 8 * 8).map(|n| n % 4 >= 2).collect();
    for (name, dtype, expect) in [
        ("voxels_bool.npz", "bool", &occupied),
        ("voxels_u8.npz", "uint8", &occupied),
        ("voxels_i32.npz", "int32", &occupied),
        ("voxels_f32.npz", "float32", &half),
        ("voxels_f64.npz", "float64", &half),
    ] {
        let a = npz::read_npz_first(&fixture(name)).unwrap();
        assert_eq!(a.shape, [2, 8, 8, 8], "{name}");
        assert_eq!(a.data.dtype_name(), dtype, "{name}");
        assert_eq!(&a.to_bools(), expect, "{name}");
    }
    let NpyData::F32(f) = npz::read_npz_first(&fixture("voxels_f32.npz"))
        .unwrap()
        .data
    else {
        panic!("float32 expected");
    };
    assert!(
        f.iter()
            .enumerate()
            .all(|(n, &x)| x == (n % 4) as f32 / 4.0)
    );

    // Several arrays: archive order (np.savez puts keyword arrays before positional ones), by
    // name, and the first is what SoftRas's loader takes.
    let mut m = Npz::open(&fixture("multi.npz")).unwrap();
    assert_eq!(m.names(), ["scalar", "arr_0", "arr_1"]);
    let first = m.first().unwrap();
    assert_eq!(
        (first.shape.len(), first.data),
        (0, NpyData::F32(vec![2.5]))
    );
    let ints: Vec<i32> = (0..10).map(|n| (n - 5) * 1_000_003).collect();
    assert_eq!(
        m.array("arr_0").unwrap(),
        NpyArray::new(vec![10], NpyData::I32(ints)).unwrap()
    );
    let floats: Vec<f64> = (0..6).map(|n| f64::from(n) * 0.5 - 1.25).collect();
    assert_eq!(
        m.array("arr_1").unwrap(),
        NpyArray::new(vec![2, 3], NpyData::F64(floats)).unwrap()
    );
    let s = m.array("scalar").unwrap();
    assert_eq!((s.shape.len(), s.data), (0, NpyData::F32(vec![2.5])));

    let s = npz::read_npy(&fixture("scalar_f64.npy")).unwrap();
    assert_eq!((s.shape.len(), s.data), (0, NpyData::F64(vec![3.25])));
    let v = npz::read_npy(&fixture("vector_f32.npy")).unwrap();
    assert_eq!(v.shape, [7]);
    assert_eq!(
        v.data,
        NpyData::F32((0..7).map(|n| n as f32 / 8.0).collect())
    );
    let b = npz::read_npy(&fixture("big_endian_f32.npy")).unwrap();
    assert_eq!(b.shape, [3, 4]);
    assert_eq!(
        b.data,
        NpyData::F32((0..12).map(|n| n as f32 / 4.0).collect())
    );
}

#[test]
fn fortran_order_other_dtypes_empty_archives_and_missing_names_are_input_errors() {
    let m = input_error(npz::read_npy(&fixture("fortran_i32.npy")));
    assert!(
        m.contains("Fortran") && m.contains("fortran_i32.npy"),
        "{m}"
    );
    let m = input_error(npz::read_npy(&fixture("int16.npy")));
    assert!(m.contains("<i2") && m.contains("int16.npy"), "{m}");
    let m = input_error(npz::read_npz_first(&fixture("empty.npz")));
    assert!(m.contains("no array") && m.contains("empty.npz"), "{m}");
    let m = input_error(npz::read_npz_array(&fixture("multi.npz"), "nope"));
    assert!(
        m.contains("nope") && m.contains("scalar, arr_0, arr_1"),
        "{m}"
    );
}

#[test]
fn malformed_npy_and_npz_files_are_one_input_error_naming_the_file() {
    let dir = TempDir::new("npz-malformed");
    let npy = std::fs::read(fixture("vector_f32.npy")).unwrap();
    let put = |name: &str, bytes: &[u8]| {
        let p = dir.path(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let mut bad_magic = npy.clone();
    bad_magic[1] = b'X';
    let header_end = npy.iter().position(|&b| b == b'\n').unwrap();
    let text = String::from_utf8_lossy(&npy[10..header_end]).to_string();
    assert!(text.contains("'descr'"), "{text}");
    let mut bad_header = npy.clone();
    let at = text.find("descr").unwrap() + 10;
    bad_header[at..at + 5].copy_from_slice(b"dexcr");
    let mut bad_dtype = npy.clone();
    let at = text.find("<f4").unwrap() + 10;
    bad_dtype[at..at + 3].copy_from_slice(b"<c8");
    let mut long = npy.clone();
    long.extend_from_slice(&[0; 4]);
    for (name, bytes, says) in [
        ("magic.npy", &bad_magic[..], "bad magic"),
        ("header.npy", &bad_header[..], "header"),
        ("dtype.npy", &bad_dtype[..], "<c8"),
        ("short.npy", &npy[..npy.len() - 3], "truncated"),
        ("long.npy", &long[..], "oversized"),
        ("cut.npy", &npy[..header_end - 5], "header"),
    ] {
        let p = put(name, bytes);
        let m = input_error(npz::read_npy(&p));
        assert!(m.contains(name) && m.contains(says), "{name}: {m}");
    }

    let archive = std::fs::read(fixture("images_u8_compressed.npz")).unwrap();
    let mut flipped = archive.clone();
    flipped[60] ^= 0x5a; // inside the deflate stream of the one entry
    let cases = [
        ("not_zip.npz", npy.clone()),
        ("cut.npz", archive[..archive.len() / 2].to_vec()),
        ("flipped.npz", flipped),
    ];
    for (name, bytes) in cases {
        let p = put(name, &bytes);
        let m = input_error(npz::read_npz_first(&p));
        assert!(m.contains(name), "{name}: {m}");
    }
    // A stored archive whose array's data no longer matches its shape (an array of 4 elements
    // saved, the shape then edited to say 5): rejected, not read short.
    let four = NpyArray::new(vec![4], NpyData::F32(vec![1.0; 4])).unwrap();
    let mut bytes = four.to_npy_bytes();
    let at = bytes.windows(5).position(|w| w == b"(4, )").unwrap();
    bytes[at + 1] = b'5';
    let p = put("shape.npy", &bytes);
    let m = input_error(npz::read_npy(&p));
    assert!(m.contains("truncated") && m.contains("[5]"), "{m}");
}

#[test]
fn rust_written_npz_reads_back_the_same_and_the_same_arrays_give_the_same_bytes() {
    let dir = TempDir::new("npz-write");
    let u8s = NpyArray::new(
        vec![2, 3, 4],
        NpyData::U8((0..24).map(|n| (n * 37 % 256) as u8).collect()),
    )
    .unwrap();
    let f32s = NpyArray::new(
        vec![3, 2],
        NpyData::F32(vec![0.5, -1.0, 3.25, 1e-7, f32::MAX, -0.0]),
    )
    .unwrap();
    let bools =
        NpyArray::new(vec![5], NpyData::Bool(vec![true, false, false, true, true])).unwrap();
    let scalar = NpyArray::new(vec![], NpyData::F64(vec![2.0])).unwrap();
    for compressed in [false, true] {
        let p = dir.path(&format!("a{compressed}.npz"));
        let arrays = [("arr_0", &u8s), ("f", &f32s), ("b", &bools), ("s", &scalar)];
        npz::write_npz(&p, &arrays, compressed).unwrap();
        let mut back = Npz::open(&p).unwrap();
        assert_eq!(back.names(), ["arr_0", "f", "b", "s"]);
        assert_eq!(back.first().unwrap(), u8s);
        assert_eq!(back.array("f").unwrap(), f32s);
        assert_eq!(back.array("b").unwrap(), bools);
        assert_eq!(back.array("s").unwrap(), scalar);
        assert_eq!(
            std::fs::read(&p).unwrap(),
            npz::npz_bytes(&arrays, compressed).unwrap(),
            "the same arrays must give the same bytes"
        );
    }
    let p = dir.path("a.npy");
    npz::write_npy(&p, &f32s).unwrap();
    assert_eq!(npz::read_npy(&p).unwrap(), f32s);
    // A shape that does not hold the data is refused before anything is written.
    let m = input_error(NpyArray::new(vec![2, 2], NpyData::U8(vec![0; 3])));
    assert!(m.contains("[2, 2]"), "{m}");
}

#[test]
fn every_category_gives_closed_outward_non_degenerate_meshes_in_the_unit_cube() {
    // 60 seeds: every style of every category (at most five per category) several times.
    for category in Category::ALL {
        for seed in 0..60u64 {
            let shape = generate(category, seed);
            let what = format!("{category} seed {seed}");
            let faces = shape.face_count();
            assert!((12..=2000).contains(&faces), "{what}: {faces} faces"); // an ottoman may be one box
            let (lo, hi) = shape.bounds();
            let mut longest = 0.0f64;
            for k in 0..3 {
                assert!(lo[k] >= -0.5 && hi[k] <= 0.5, "{what}: {lo:?} {hi:?}");
                // Centred: the bounding box is symmetric about the origin.
                assert!((lo[k] + hi[k]).abs() < 1e-5, "{what}: {lo:?} {hi:?}");
                longest = longest.max(hi[k] - lo[k]);
            }
            assert!(
                (longest - 0.98).abs() < 1e-5,
                "{what}: longest side {longest}"
            );
            for (i, part) in shape.parts.iter().enumerate() {
                let p: Vec<DVec3> = part
                    .positions
                    .iter()
                    .map(|v| DVec3::from(v.map(f64::from)))
                    .collect();
                let mut volume = 0.0;
                let mut edges = std::collections::HashMap::new();
                for f in &part.faces {
                    let [a, b, c] = f.map(|i| p[i as usize]);
                    let area = (b - a).cross(c - a).length() / 2.0;
                    assert!(area > 1e-7, "{what} part {i}: degenerate face {f:?}");
                    volume += a.dot(b.cross(c)) / 6.0;
                    for e in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
                        *edges.entry(e).or_insert(0) += 1;
                    }
                }
                // Closed and consistently wound: every directed edge once, its reverse once.
                for (&(a, b), &n) in &edges {
                    assert_eq!(n, 1, "{what} part {i}: edge {a}-{b} used {n} times");
                    assert_eq!(edges.get(&(b, a)), Some(&1), "{what} part {i}: open edge");
                }
                assert!(volume > 1e-6, "{what} part {i}: volume {volume} (inward?)");
                assert!(part.color.iter().all(|c| (0.0..=1.0).contains(c)));
            }
            let mesh = shape.mesh().unwrap();
            assert_eq!(mesh.texture_res, 1);
            assert_eq!(mesh.textures.len(), faces);
            let occ = shape
                .voxelize(&dataset::voxel_cube(), VOXEL_RES as u32)
                .unwrap();
            assert!(occ.count() > 20, "{what}: {} voxels", occ.count());
        }
    }
}

/// The plane through `a`, `b`, `c` (unit normal n, offset n · a).
fn plane(a: DVec3, b: DVec3, c: DVec3) -> (DVec3, f64) {
    let n = (b - a).cross(c - a).normalize();
    (n, n.dot(a))
}

/// The thinnest a part is, between opposite faces: the least distance from a corner of a face
/// to the plane of the face across from it. A part is one of the generator's two primitives,
/// told apart by their corner counts: a hexahedron (8 corners, corner i at bits x, y, z of i, as
/// the generator's boxes number them; faces across from each other differ in one bit), or a
/// cylinder or cone of n sides (two rings of n, then the two end centres; side quad k is across
/// from side quad k + n/2, one end from the other). So a box gives its shortest side, a wing
/// its thickness and its chord at the tip, a cylinder its width across flats, a cone that width
/// at its narrow end, square to its side, and a leaning slab its thickness square to its faces.
fn thinnest(part: &Part) -> f64 {
    let p: Vec<DVec3> = part
        .positions
        .iter()
        .map(|v| DVec3::from(v.map(f64::from)))
        .collect();
    let dist = |(n, d): (DVec3, f64), i: usize| (d - n.dot(p[i])).abs();
    let mut thinnest = f64::INFINITY;
    if p.len() == 8 {
        for bit in [1, 2, 4] {
            let side =
                |set: bool| -> Vec<usize> { (0..8).filter(|i| (i & bit != 0) == set).collect() };
            for (from, to) in [(side(false), side(true)), (side(true), side(false))] {
                let pl = plane(p[to[0]], p[to[1]], p[to[3]]);
                for &i in &from {
                    thinnest = thinnest.min(dist(pl, i));
                }
            }
        }
    } else {
        assert!(p.len() % 2 == 0 && p.len() >= 8, "{} corners", p.len());
        let n = (p.len() - 2) / 2;
        let (c0, c1) = (2 * n, 2 * n + 1);
        // The ends' centres lie on their rings' planes, so the length is theirs apart.
        thinnest = thinnest.min((p[c1] - p[c0]).length());
        let quad = |k: usize| [k % n, (k + 1) % n, n + (k + 1) % n, n + k % n];
        for k in 0..n {
            let across = quad(k + n / 2);
            let pl = plane(p[across[0]], p[across[1]], p[across[2]]);
            for i in quad(k) {
                thinnest = thinnest.min(dist(pl, i));
            }
        }
    }
    thinnest
}

#[test]
fn every_part_of_every_category_is_at_least_min_thickness_thick() {
    // 300 seeds a category: every style, and the extremes of the continuous parameters
    // (tapers, radii, thicknesses drawn at their minimum) often enough to meet them.
    let mut failures = Vec::new();
    for category in Category::ALL {
        // The thinnest hexahedron (slabs, legs, wings) and the thinnest cylinder or cone apart,
        // so that a failure names both kinds.
        let mut worst: [Option<(f64, u64, usize)>; 2] = [None; 2];
        for seed in 0..300u64 {
            for (i, part) in generate(category, seed).parts.iter().enumerate() {
                let t = thinnest(part);
                let w = &mut worst[usize::from(part.positions.len() != 8)];
                if w.is_none_or(|w| t < w.0) {
                    *w = Some((t, seed, i));
                }
            }
        }
        for (kind, w) in ["hexahedron", "cylinder or cone"].iter().zip(worst) {
            if let Some((t, seed, i)) = w
                && t < MIN_THICKNESS
            {
                failures.push(format!("{category} seed {seed} part {i} ({kind}): {t:.4}"));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "thinner than {MIN_THICKNESS}: {failures:?}"
    );
}

#[test]
fn seeds_change_the_shapes_and_the_same_seed_repeats_them_bit_for_bit() {
    for category in Category::ALL {
        assert_eq!(generate(category, 7), generate(category, 7), "{category}");
        let a = generate(category, 7).mesh().unwrap();
        let b = generate(category, 8).mesh().unwrap();
        assert!(
            a.positions != b.positions,
            "{category}: seeds 7 and 8 agree"
        );
        assert!(
            a.textures != b.textures,
            "{category}: same colours for seeds 7 and 8"
        );
    }
    // The object of a split does not depend on the other splits' counts.
    let o = DatasetOptions {
        train: 3,
        val: 8,
        test: 1,
        ..DatasetOptions::default()
    };
    let more = DatasetOptions {
        train: 2,
        val: 5,
        test: 0,
        ..DatasetOptions::default()
    };
    assert_eq!(
        dataset::split_shapes(&o, Category::Chair, Split::Val)[..5],
        dataset::split_shapes(&more, Category::Chair, Split::Val)[..]
    );
}

#[test]
fn dataset_voxel_order_puts_world_axes_where_voxel_center_says() {
    // An asymmetric region: x > 0.1, y < 0, z > 0.25 (a corner block), sampled at the lattice.
    let inside = |p: [f64; 3]| p[0] > 0.1 && p[1] < 0.0 && p[2] > 0.25;
    let occ = occupancy_from_fn(&dataset::voxel_cube(), VOXEL_RES as u32, inside);
    let nmr = dataset::occupancy_to_nmr(&occ).unwrap();
    let r = VOXEL_RES;
    let mut n = 0;
    for a in 0..r {
        for b in 0..r {
            for c in 0..r {
                let expect = inside(voxel_center(a, b, c));
                assert_eq!(nmr[(a * r + b) * r + c], expect, "[{a}][{b}][{c}]");
                n += usize::from(expect);
            }
        }
    }
    assert!(n > 100);
    // SoftRas's lattice: centres from −0.5 to 0.5 in steps of 1/31, axis 0 up, axis 2 towards −z.
    assert_eq!(voxel_center(0, 0, 0), [-0.5, -0.5, 0.5]);
    assert_eq!(voxel_center(31, 31, 31), [0.5, 0.5, -0.5]);
}

/// The rendered alpha > 0.5 against the voxels' silhouette seen through the camera of view v
/// under a convention: `azimuth_sign` −1 (SoftRas's) or +1, `center` the voxel index → world map.
fn silhouette_iou(
    alpha: &[u8],
    voxels: &[bool],
    view: usize,
    azimuth_sign: f64,
    center: &dyn Fn(usize, usize, usize) -> [f64; 3],
) -> f64 {
    let mut camera = Camera::from_angles(2.732, 30.0, azimuth_sign * 15.0 * view as f64);
    camera.projection = Projection::Perspective {
        viewing_angle_deg: 15.0,
    };
    let s = IMAGE_SIZE;
    let mut mask = vec![false; s * s];
    let r = VOXEL_RES;
    let step = 1.0 / 31.0;
    for a in 0..r {
        for b in 0..r {
            for c in 0..r {
                if !voxels[(a * r + b) * r + c] {
                    continue;
                }
                let p = DVec3::from(center(a, b, c));
                // The voxel's cell, sampled 4 × 4 × 4 so it covers its pixels without holes.
                for o in 0..64 {
                    let off = DVec3::new(
                        (o % 4) as f64 - 1.5,
                        (o / 4 % 4) as f64 - 1.5,
                        (o / 16) as f64 - 1.5,
                    ) * (step / 4.0);
                    let [x, y, _] = camera.to_screen(p + off);
                    // SPEC §1 pixel centres: x_p = (2c + 1 − S)/S, y_p = (2(S − 1 − r) + 1 − S)/S.
                    let col = ((x * s as f64 + s as f64 - 1.0) / 2.0).round();
                    let row = (s as f64 - 1.0) - ((y * s as f64 + s as f64 - 1.0) / 2.0).round();
                    if (0.0..s as f64).contains(&col) && (0.0..s as f64).contains(&row) {
                        mask[row as usize * s + col as usize] = true;
                    }
                }
            }
        }
    }
    let (mut both, mut any) = (0, 0);
    for (m, &a) in mask.iter().zip(alpha) {
        let r = a > 127;
        both += usize::from(*m && r);
        any += usize::from(*m || r);
    }
    both as f64 / any.max(1) as f64
}

#[test]
fn rendered_alpha_agrees_with_the_voxels_under_softras_conventions_only() {
    let Some(gpu) = common::gpu() else { return };
    let renderer = Renderer::new(&gpu).unwrap();
    let options = DatasetOptions::default();
    // Objects without a symmetry that would hide a wrong convention (a straight lamp is the same
    // from every azimuth).
    let shapes: Vec<_> = [Category::Chair, Category::Airplane, Category::Car]
        .iter()
        .map(|&c| generate(c, 3))
        .collect();
    let images = dataset::render_shapes(&gpu, &renderer, &shapes, &options).unwrap();
    let voxels = dataset::voxelize_shapes(&shapes).unwrap();
    assert_eq!(
        images.len(),
        shapes.len() * VIEWS * 4 * IMAGE_SIZE * IMAGE_SIZE
    );
    let plane = IMAGE_SIZE * IMAGE_SIZE;
    let f = |n: f64| (n - 15.5) / 31.0;
    // SoftRas's evaluation order, written out here independently of the library.
    let softras = |a: usize, b: usize, c: usize| [f(b as f64), f(a as f64), -f(c as f64)];
    let no_flip = |a: usize, b: usize, c: usize| [f(b as f64), f(a as f64), f(c as f64)];
    let swapped = |a: usize, b: usize, c: usize| [f(a as f64), f(b as f64), -f(c as f64)];
    // Mean IoUs over the objects: right, azimuth +15v, z unflipped, x/y swapped.
    let mut means = [0.0; 4];
    for (n, shape) in shapes.iter().enumerate() {
        let vox = &voxels[n * VOXEL_RES.pow(3)..(n + 1) * VOXEL_RES.pow(3)];
        let mut sums = [0.0; 4];
        for v in 0..VIEWS {
            let base = (n * VIEWS + v) * 4 * plane;
            let alpha = &images[base + 3 * plane..base + 4 * plane];
            assert!(alpha.iter().any(|&a| a > 127) && alpha.contains(&0));
            sums[0] += silhouette_iou(alpha, vox, v, -1.0, &softras);
            sums[1] += silhouette_iou(alpha, vox, v, 1.0, &softras);
            sums[2] += silhouette_iou(alpha, vox, v, -1.0, &no_flip);
            sums[3] += silhouette_iou(alpha, vox, v, -1.0, &swapped);
        }
        let [right, az, flip, swap] = sums.map(|s| s / VIEWS as f64);
        let what = shape.category;
        eprintln!(
            "{what}: IoU {right:.3}; azimuth +15v {az:.3}, z unflipped {flip:.3}, \
             x/y swapped {swap:.3}"
        );
        assert!(right > 0.8, "{what}: silhouette IoU {right:.3}");
        for (m, x) in means.iter_mut().zip([right, az, flip, swap]) {
            *m += x / shapes.len() as f64;
        }
    }
    // A car is nearly the same front and back, so each wrong convention is judged over all.
    let [right, wrong @ ..] = means;
    for (name, w) in ["azimuth +15v", "z unflipped", "x/y swapped"]
        .iter()
        .zip(wrong)
    {
        assert!(
            w < right - 0.15,
            "{name} gives mean IoU {w:.3}, too close to the right {right:.3}"
        );
    }
}

#[test]
fn dataset_round_trips_and_the_same_seed_writes_the_same_bytes() {
    let Some(gpu) = common::gpu() else { return };
    let dir = TempDir::new("dataset");
    let options = DatasetOptions {
        categories: vec![Category::Table, Category::Car],
        train: 2,
        val: 1,
        test: 0,
        // Both training tables stand on four legs (checked below).
        seed: 9,
        ..DatasetOptions::default()
    };
    let (a, b) = (dir.path("a"), dir.path("b"));
    let mut calls = Vec::new();
    let files = dataset::write_dataset(&gpu, &a, &options, &mut |c, s, n| {
        calls.push((c, s, n));
        true
    })
    .unwrap();
    assert_eq!(
        calls,
        [
            (Category::Table, Split::Train, 2),
            (Category::Table, Split::Val, 1),
            (Category::Car, Split::Train, 2),
            (Category::Car, Split::Val, 1),
        ]
    );
    assert_eq!(files.len(), 8);
    // The bytes do not depend on how many objects render together.
    let batched = DatasetOptions {
        batch: 3,
        ..options.clone()
    };
    let files_b = dataset::write_dataset(&gpu, &b, &batched, &mut |_, _, _| true).unwrap();
    for (fa, fb) in files.iter().zip(&files_b) {
        assert_eq!(fa.file_name(), fb.file_name());
        assert!(
            std::fs::read(fa).unwrap() == std::fs::read(fb).unwrap(),
            "{} differs between two runs of the same objects",
            fa.display()
        );
    }
    let names: Vec<_> = std::fs::read_dir(&a)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert!(names.iter().all(|n| !n.starts_with('.')), "{names:?}");
    assert!(names.contains(&"04379243_train_images.npz".to_string()));
    assert!(names.contains(&"02958343_val_voxels.npz".to_string()));

    let images = npz::read_npz_first(&a.join("02958343_train_images.npz")).unwrap();
    assert_eq!(images.shape, [2, VIEWS, 4, IMAGE_SIZE, IMAGE_SIZE]);
    assert_eq!(images.data.dtype_name(), "uint8");
    let voxels = npz::read_npz_first(&a.join("02958343_train_voxels.npz")).unwrap();
    assert_eq!(voxels.shape, [2, 32, 32, 32]);
    assert_eq!(voxels.data.dtype_name(), "uint8");

    let train = Dataset::open(&a, Split::Train).unwrap();
    let ids: Vec<_> = train.classes.iter().map(|c| c.class_id.as_str()).collect();
    assert_eq!(ids, ["02958343", "04379243"]);
    for class in &train.classes {
        assert_eq!(class.count, 2);
        assert_eq!(class.images.len(), 2 * VIEWS * 4 * IMAGE_SIZE * IMAGE_SIZE);
        assert_eq!(class.voxels.len(), 2 * 32 * 32 * 32);
        let c = class.category.unwrap();
        // What was written is what the generator and voxelizer give for the object's seed.
        let shapes = dataset::split_shapes(&options, c, Split::Train);
        assert_eq!(class.voxels, dataset::voxelize_shapes(&shapes).unwrap());
        assert!(class.voxels_of(1).iter().any(|&x| x));
        assert_eq!(class.image(1, 5).len(), 4 * IMAGE_SIZE * IMAGE_SIZE);
    }
    // The visual hull of an object's own 24 silhouettes: a car's is close (only the hollow
    // under its body between the wheels is left uncarved), a legged table's is not (every view
    // looks down on its top, so the space between its legs stays). Wrong cameras or a wrong
    // voxel order would carve the objects away. This seed's two tables both stand on four legs
    // (four parts reach the floor; a pedestal or slab-ended table, whose hull comes closer,
    // has two).
    for shape in dataset::split_shapes(&options, Category::Table, Split::Train) {
        let floor = shape.bounds().0[1];
        let on_floor = |p: &Part| p.positions.iter().any(|q| f64::from(q[1]) < floor + 1e-3);
        assert_eq!(shape.parts.iter().filter(|p| on_floor(p)).count(), 4);
    }
    let hull = |c: usize| -> Vec<f64> {
        (0..2)
            .map(|n| eval::visual_hull_iou(&train.classes[c], n).unwrap())
            .collect()
    };
    let (car, table) = (hull(0), hull(1));
    assert!(car.iter().all(|&h| h > 0.6), "car hulls {car:?}");
    assert!(table.iter().all(|&h| h < 0.55), "table hulls {table:?}");
    assert_eq!(Dataset::open(&a, Split::Val).unwrap().classes[0].count, 1);
    let m = input_error(Dataset::open(&a, Split::Test));
    assert!(m.contains("no *_test_images.npz"), "{m}");

    // Another seed, other objects.
    let c = dir.path("c");
    let other = DatasetOptions {
        seed: 12,
        categories: vec![Category::Car],
        val: 0,
        ..options.clone()
    };
    dataset::write_dataset(&gpu, &c, &other, &mut |_, _, _| true).unwrap();
    let name = "02958343_train_images.npz";
    assert!(std::fs::read(a.join(name)).unwrap() != std::fs::read(c.join(name)).unwrap());
}

#[test]
fn dataset_open_rejects_files_whose_shapes_disagree() {
    let dir = TempDir::new("dataset-bad");
    let images = |n: usize, views: usize| {
        NpyArray::new(
            vec![n, views, 4, 64, 64],
            NpyData::U8(vec![0; n * views * 4 * 64 * 64]),
        )
        .unwrap()
    };
    let voxels = |n: usize, r: usize| {
        NpyArray::new(vec![n, r, r, r], NpyData::F32(vec![1.0; n * r * r * r])).unwrap()
    };
    let case = |tag: &str, im: NpyArray, vox: Option<NpyArray>, says: &str| {
        let d = dir.path(tag);
        std::fs::create_dir_all(&d).unwrap();
        npz::write_npz(&d.join("01_train_images.npz"), &[("arr_0", &im)], true).unwrap();
        if let Some(v) = vox {
            npz::write_npz(&d.join("01_train_voxels.npz"), &[("arr_0", &v)], true).unwrap();
        }
        let m = input_error(Dataset::open(&d, Split::Train));
        assert!(m.contains(says), "{tag}: {m}");
    };
    case("count", images(2, 24), Some(voxels(3, 32)), "3 objects");
    case(
        "views",
        images(2, 23),
        Some(voxels(2, 32)),
        "images of shape [2, 23, 4, 64, 64]",
    );
    case(
        "res",
        images(1, 24),
        Some(voxels(1, 16)),
        "voxels of shape [1, 16, 16, 16]",
    );
    case("missing", images(1, 24), None, "missing");
    // Float voxels read as occupancy; SoftRas's (N·24, 4, 64, 64) layout is accepted.
    let d = dir.path("ok");
    std::fs::create_dir_all(&d).unwrap();
    let flat = NpyArray::new(vec![48, 4, 64, 64], NpyData::U8(vec![9; 48 * 4 * 64 * 64])).unwrap();
    npz::write_npz(&d.join("01_val_images.npz"), &[("arr_0", &flat)], false).unwrap();
    npz::write_npz(
        &d.join("01_val_voxels.npz"),
        &[("arr_0", &voxels(2, 32))],
        false,
    )
    .unwrap();
    let ok = Dataset::open(&d, Split::Val).unwrap();
    assert_eq!(ok.classes[0].count, 2);
    assert!(ok.classes[0].voxels.iter().all(|&x| x));
    assert_eq!(ok.classes[0].category, None);
}

#[test]
fn int64_arrays_round_trip_through_npy_bytes() {
    let array = NpyArray::new(vec![2, 3], NpyData::I64(vec![-1, 0, 7, 1 << 40, -5, 3])).unwrap();
    let bytes = array.to_npy_bytes();
    assert!(String::from_utf8_lossy(&bytes[..64]).contains("<i8"));
    assert_eq!(NpyArray::from_npy_bytes(&bytes, "x.npy").unwrap(), array);
    assert_eq!(array.data.dtype_name(), "int64");
}

/// `--batch 16` on twelve objects of one topology: more views than one scene's storage bindings
/// hold on lavapipe (their super-sampled pixels' aux alone is 192 MiB against 128), so they
/// render in as many scenes as fit, with the bytes of one object at a time (the batch used to
/// overflow the binding, after earlier classes' files were written).
#[test]
fn a_batch_past_the_storage_bindings_renders_in_parts_with_the_same_bytes() {
    let Some(gpu) = common::gpu() else { return };
    let renderer = Renderer::new(&gpu).unwrap();
    let shape = generate(Category::Car, 5);
    let shapes = vec![shape; 12];
    let options = |batch| DatasetOptions {
        batch,
        ..DatasetOptions::default()
    };
    let settings = dataset::raster_settings(&options(1));
    let faces = shapes[0].face_count() as u64;
    let fits = softvk::raster::gpu::views_per_scene(&gpu, faces, &settings) / VIEWS;
    if fits >= 12 {
        eprintln!("SKIPPED: this device's storage bindings hold {fits} objects' views at once");
        return;
    }
    let one = dataset::render_shapes(&gpu, &renderer, &shapes, &options(1)).unwrap();
    let many = dataset::render_shapes(&gpu, &renderer, &shapes, &options(16)).unwrap();
    assert!(one == many, "a batch of 16 rendered other bytes");
    assert!(one.iter().any(|&x| x > 0));
}
