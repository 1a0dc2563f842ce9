//! Cube maps on the GPU (`softvk::raster::hard::gpu::texture`, `TexMode::Cube`) against their
//! f64 twin (`softvk::raster::hard::texture::cube`): every filter mode, one and three channels,
//! a shared cube and one per minibatch item, at and between mip levels with `uv_da`, a bias or
//! both, on a stack built here and on one given level by level; the gradients to the texels,
//! the direction, `uv_da` and the bias; a sweep across every face edge with no seam; and the
//! golden bytes at every lane count and workgroup shape.
//!
//! Directions are exact in f32: a major component of ±2^k and the others on a grid of 1/4096
//! times it, some exactly on a face edge or a cube corner (the tie rules), so f32 takes the
//! faces, texels and fractions f64 does and the bounds hold the arithmetic after them. Lookups
//! within 1e-4 of an integer level, where the two may take different levels, are skipped and
//! counted.

mod common;

use common::hard::fnv1a;

use rand::RngExt;
use softvk::raster::hard::gpu::texture::{
    Levels, Lookup, Lookups, TexLayout, TexMode, TextureGrads32, TextureSampler,
};
use softvk::raster::hard::texture::{
    CubeLevelInput, Filter, MipStack, cube_direction, cube_level_of_detail, sample_cube,
    sample_cube_backward,
};

const FILTERS: [Filter; 4] = [
    Filter::Nearest,
    Filter::Linear,
    Filter::LinearMipmapNearest,
    Filter::LinearMipmapLinear,
];

/// One case: a cube map, its stack in f64 and the lookups.
struct Case {
    layout: TexLayout,
    tex: Vec<f32>,
    stack: MipStack,
    grid: Lookups,
    dir: Vec<f32>,
    uv_da: Option<Vec<f32>>,
    bias: Option<Vec<f32>>,
}

impl Case {
    /// `cubes` cubes of `size²` faces of `c` channels (levels by `max_mip_level`), lookups
    /// `[2, 7, 9]`.
    fn new(
        seed: u64,
        [cubes, size, c]: [u32; 3],
        max_mip_level: Option<u32>,
        level_inputs: (bool, bool),
    ) -> Self {
        let mut rng = common::rng(seed);
        let layout = TexLayout::with_mips(6 * cubes, size, size, c, max_mip_level).unwrap();
        let n0 = layout.level_texels(0) as usize * c as usize;
        let tex: Vec<f32> = (0..n0).map(|_| rng.random_range(-1.0..1.0)).collect();
        let stack = MipStack::cube(
            cubes as usize,
            size as usize,
            c as usize,
            tex.iter().map(|&v| f64::from(v)).collect(),
        )
        .unwrap()
        .build(max_mip_level)
        .unwrap();
        let grid = Lookups {
            batch: 2,
            height: 7,
            width: 9,
            uv_da: level_inputs.0,
            bias: level_inputs.1,
        };
        let points = grid.points() as usize;
        let mut dir = Vec::with_capacity(3 * points);
        for i in 0..points {
            let major = rng.random_range(0..3usize);
            let scale = 2f32.powi(rng.random_range(-1..3));
            let mut d = [0.0f32; 3];
            for (k, v) in d.iter_mut().enumerate() {
                *v = if k == major {
                    if rng.random_bool(0.5) { 1.0 } else { -1.0 }
                } else {
                    (rng.random_range(-1.0f32..1.0) * 4096.0).round() / 4096.0
                };
            }
            // Every ninth on a face edge, every 21st on a cube corner.
            if i % 9 == 4 {
                d[(major + 1) % 3] = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            }
            if i % 21 == 10 {
                d = [1.0, -1.0, 1.0];
            }
            dir.extend(d.map(|v| v * scale));
        }
        // Footprints from a tenth of a texel to the whole face, anisotropic.
        let uv_da = level_inputs.0.then(|| {
            (0..points)
                .flat_map(|i| {
                    let m = (0..3).map(|k| dir[3 * i + k].abs()).fold(0.0, f32::max);
                    let scale = 2.0 * m * 2f32.powf(rng.random_range(-3.5..1.0)) / size as f32;
                    let a: [f32; 6] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
                    a.map(|v| v * scale)
                })
                .collect()
        });
        let bias = level_inputs
            .1
            .then(|| (0..points).map(|_| rng.random_range(-1.0..3.0)).collect());
        Self {
            layout,
            tex,
            stack,
            grid,
            dir,
            uv_da,
            bias,
        }
    }

    fn lookup(&self) -> Lookup<'_> {
        Lookup {
            grid: self.grid,
            uv: &self.dir,
            uv_da: self.uv_da.as_deref(),
            bias: self.bias.as_deref(),
        }
    }

    fn points(&self) -> usize {
        self.grid.points() as usize
    }

    fn item(&self, i: usize) -> usize {
        i / (self.grid.height * self.grid.width) as usize
    }

    fn dir_at(&self, i: usize) -> [f64; 3] {
        std::array::from_fn(|k| f64::from(self.dir[3 * i + k]))
    }

    fn level_at(&self, i: usize) -> CubeLevelInput {
        CubeLevelInput {
            uv_da: self
                .uv_da
                .as_ref()
                .map(|d| std::array::from_fn(|k| f64::from(d[6 * i + k]))),
            bias: self.bias.as_ref().map(|b| f64::from(b[i])),
        }
    }

    fn stack_f32(&self) -> Vec<f32> {
        self.stack
            .levels
            .iter()
            .flat_map(|l| l.texels.iter().map(|&v| v as f32))
            .collect()
    }

    /// Whether lookup `i`'s level lies within `margin` of an integer.
    fn near_integer_level(&self, i: usize, filter: Filter, margin: f64) -> bool {
        if !filter.uses_mips() {
            return false;
        }
        let size = self.stack.levels[0].width;
        let raw = cube_level_of_detail(self.dir_at(i), self.level_at(i), size);
        let top = self.stack.max_level() as f64;
        (raw - raw.round()).abs() < margin && raw > -margin && raw < top + margin
    }
}

/// The cases every comparison runs.
fn cases(filter: Filter) -> Vec<(String, Case)> {
    let level_inputs: Vec<(bool, bool)> = if filter.uses_mips() {
        vec![(true, false), (false, true), (true, true)]
    } else {
        vec![(false, false)]
    };
    let mut out = Vec::new();
    for (k, &inputs) in level_inputs.iter().enumerate() {
        let seed = 31 * k as u64;
        // Down to 1 × 1 faces, where every lookup's taps pass an edge or a corner.
        out.push((
            format!("shared 8² x3, levels {inputs:?}"),
            Case::new(seed, [1, 8, 3], None, inputs),
        ));
        out.push((
            format!("per-item 4² x1, levels {inputs:?}"),
            Case::new(seed + 1, [2, 4, 1], None, inputs),
        ));
    }
    if !filter.uses_mips() {
        // Not a power of two (no mip levels).
        out.push((
            "shared 6² x2".into(),
            Case::new(77, [1, 6, 2], Some(0), (false, false)),
        ));
    }
    out
}

#[test]
fn every_cube_mode_samples_as_the_twin() {
    let Some(ctx) = common::gpu() else { return };
    let mut sampler = TextureSampler::new(&ctx).unwrap();
    let (mut checked, mut skipped) = (0usize, 0usize);
    let mut worst = 0.0f64;
    for filter in FILTERS {
        let mode = TexMode::Cube(filter);
        for (name, case) in cases(filter) {
            let stack = case.stack_f32();
            let built = sampler
                .sample(
                    &ctx,
                    &case.layout,
                    mode,
                    Levels::Build(&case.tex),
                    &case.lookup(),
                )
                .unwrap();
            let given = sampler
                .sample(
                    &ctx,
                    &case.layout,
                    mode,
                    Levels::Given(&stack),
                    &case.lookup(),
                )
                .unwrap();
            let c = case.layout.channels as usize;
            for i in 0..case.points() {
                if case.near_integer_level(i, filter, 1e-4) {
                    skipped += 1;
                    continue;
                }
                checked += 1;
                let twin = sample_cube(
                    &case.stack,
                    case.item(i),
                    case.dir_at(i),
                    case.level_at(i),
                    filter,
                )
                .unwrap();
                for k in 0..c {
                    for (what, out) in [("built", &built), ("given", &given)] {
                        let e = (f64::from(out[i * c + k]) - twin[k]).abs();
                        worst = worst.max(e);
                        assert!(
                            e <= 4e-7,
                            "{filter:?} {name} ({what} stack): lookup {i} {:?} channel {k}: \
                             GPU {} twin {}",
                            case.dir_at(i),
                            out[i * c + k],
                            twin[k]
                        );
                    }
                }
            }
        }
    }
    eprintln!("cube forward: {checked} lookups checked, {skipped} skipped, worst {worst:.2e}");
    assert!(
        skipped * 20 < checked,
        "{checked} checked, {skipped} skipped"
    );
}

/// The twin's backward: every level's texel gradients (before the pyramid) and the lookups'
/// own.
struct TwinGrads {
    levels: Vec<Vec<f64>>,
    dir: Vec<[f64; 3]>,
    uv_da: Vec<[f64; 6]>,
    bias: Vec<f64>,
}

fn twin_grads(case: &Case, filter: Filter, dy: &[f32], stack: &MipStack) -> TwinGrads {
    let c = case.layout.channels as usize;
    let mut levels = stack.zero_grads();
    let (mut dir, mut uv_da, mut bias) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..case.points() {
        let d: Vec<f64> = dy[i * c..(i + 1) * c]
            .iter()
            .map(|&v| f64::from(v))
            .collect();
        let p = sample_cube_backward(
            stack,
            case.item(i),
            case.dir_at(i),
            case.level_at(i),
            filter,
            &d,
            &mut levels,
        )
        .unwrap();
        dir.push(p.dir);
        uv_da.push(p.uv_da);
        bias.push(p.bias);
    }
    TwinGrads {
        levels,
        dir,
        uv_da,
        bias,
    }
}

#[test]
fn every_cube_gradient_matches_the_twin() {
    let Some(ctx) = common::gpu() else { return };
    let mut sampler = TextureSampler::new(&ctx).unwrap();
    let (mut checked, mut skipped) = (0usize, 0usize);
    let mut worst = [0.0f64; 4];
    for filter in FILTERS {
        let mode = TexMode::Cube(filter);
        for (name, case) in cases(filter) {
            let c = case.layout.channels as usize;
            let mut rng = common::rng(5);
            let dy: Vec<f32> = (0..case.points() * c)
                .map(|_| rng.random_range(-1.0..1.0))
                .collect();
            let stack = case.stack_f32();
            let what = format!("{filter:?} {name}");
            let twin = twin_grads(&case, filter, &dy, &case.stack);
            // Sizes: the same sums over |dy| and |texels|.
            let abs_dy: Vec<f32> = dy.iter().map(|v| v.abs()).collect();
            let mut abs_stack = case.stack.clone();
            for l in &mut abs_stack.levels {
                l.texels.iter_mut().for_each(|v| *v = v.abs());
            }
            let size = twin_grads(&case, filter, &abs_dy, &abs_stack);
            let given = sampler
                .sample_grad(
                    &ctx,
                    &case.layout,
                    mode,
                    Levels::Given(&stack),
                    &case.lookup(),
                    &dy,
                )
                .unwrap();
            let built = sampler
                .sample_grad(
                    &ctx,
                    &case.layout,
                    mode,
                    Levels::Build(&case.tex),
                    &case.lookup(),
                    &dy,
                )
                .unwrap();
            for i in 0..case.points() {
                if case.near_integer_level(i, filter, 1e-4) {
                    skipped += 1;
                    continue;
                }
                checked += 1;
                for g in [&given, &built] {
                    for k in 0..3 {
                        let e = (f64::from(g.uv[3 * i + k]) - twin.dir[i][k]).abs();
                        let s = size.dir[i][k].abs() + twin.dir[i][k].abs() + 1.0;
                        worst[0] = worst[0].max(e / s);
                        assert!(
                            e <= 1.5e-5 * s,
                            "{what}: d/ddir[{i}][{k}] at {:?}: GPU {} twin {}",
                            case.dir_at(i),
                            g.uv[3 * i + k],
                            twin.dir[i][k]
                        );
                    }
                    if case.grid.uv_da {
                        for k in 0..6 {
                            let e = (f64::from(g.uv_da[6 * i + k]) - twin.uv_da[i][k]).abs();
                            let s = twin.uv_da[i][k].abs() + 1.0;
                            worst[1] = worst[1].max(e / s);
                            assert!(
                                e <= 1e-5 * s,
                                "{what}: d/duv_da[{i}][{k}] GPU {} twin {}",
                                g.uv_da[6 * i + k],
                                twin.uv_da[i][k]
                            );
                        }
                    }
                    if case.grid.bias {
                        let e = (f64::from(g.bias[i]) - twin.bias[i]).abs();
                        let s = size.bias[i].abs() + 1.0;
                        worst[2] = worst[2].max(e / s);
                        assert!(
                            e <= 2e-7 * s,
                            "{what}: d/dbias[{i}] GPU {} twin {}",
                            g.bias[i],
                            twin.bias[i]
                        );
                    }
                }
            }
            // The texels': every level of the given stack, and the built one's carried into
            // its base.
            let mut at = 0;
            let base_grad = case.stack.pyramid_backward(twin.levels.clone());
            let base_size = case.stack.pyramid_backward(size.levels.clone());
            for (l, (t, s)) in twin.levels.iter().zip(&size.levels).enumerate() {
                for (j, (t, s)) in t.iter().zip(s).enumerate() {
                    let e = (f64::from(given.stack[at + j]) - t).abs();
                    worst[3] = worst[3].max(e / (s + 5e-2));
                    assert!(
                        e <= 2e-6 * s + 1e-7,
                        "{what}: given level {l} texel float {j}: GPU {} twin {t}",
                        given.stack[at + j]
                    );
                }
                at += t.len();
            }
            for (j, (t, s)) in base_grad.iter().zip(&base_size).enumerate() {
                let e = (f64::from(built.stack[j]) - t).abs();
                assert!(
                    e <= 2e-6 * s + 1e-7,
                    "{what}: built base texel float {j}: GPU {} twin {t}",
                    built.stack[j]
                );
            }
        }
    }
    eprintln!(
        "cube backward: {checked} lookups checked, {skipped} skipped; worst relative dir \
         {:.2e}, uv_da {:.2e}, bias {:.2e}, texels {:.2e}",
        worst[0], worst[1], worst[2], worst[3]
    );
    assert!(
        skipped * 10 < checked,
        "{checked} checked, {skipped} skipped"
    );
}

/// A direction swept across each of the cube's 12 edges (from both faces' sides, near the
/// middle and near both corners), 400 steps over 0.4 of a face, on the GPU: each step changes
/// the result by no more than the texels' slope allows (a seam would jump by up to the
/// difference of two texels, about 1), in 'linear' and on the mip levels.
#[test]
fn a_cube_map_sampled_on_the_gpu_has_no_seam() {
    let Some(ctx) = common::gpu() else { return };
    let mut sampler = TextureSampler::new(&ctx).unwrap();
    let (n, c) = (8u32, 2u32);
    let steps = 400usize;
    let case = Case::new(3, [1, n, c], None, (false, false));
    let mut dirs = Vec::new();
    let mut sweeps = 0;
    for face in 0..6 {
        for across in [0, 1] {
            for sign in [1.0, -1.0] {
                for along in [0.3, 0.03, 0.97] {
                    sweeps += 1;
                    for k in 0..steps {
                        let x = 0.4 * (k as f64 / (steps - 1) as f64) - 0.2;
                        let out = 0.5 + sign * (0.5 + x);
                        let (s, t) = if across == 0 {
                            (out, along)
                        } else {
                            (along, out)
                        };
                        dirs.extend(cube_direction(face, s, t).map(|v| v as f32));
                    }
                }
            }
        }
    }
    let points = dirs.len() / 3;
    for (filter, bias) in [
        (Filter::Linear, 0.0f32),
        (Filter::LinearMipmapNearest, 2.0),
        (Filter::LinearMipmapLinear, 1.5),
    ] {
        let biases = vec![bias; points];
        let lookup = Lookup {
            grid: Lookups {
                batch: 1,
                height: sweeps,
                width: steps as u32,
                uv_da: false,
                bias: filter.uses_mips(),
            },
            uv: &dirs,
            uv_da: None,
            bias: filter.uses_mips().then_some(&biases[..]),
        };
        let out = sampler
            .sample(
                &ctx,
                &case.layout,
                TexMode::Cube(filter),
                Levels::Build(&case.tex),
                &lookup,
            )
            .unwrap();
        // One step moves the lookup by 0.4 / 399 of a face, twice that in s and t together
        // past an edge near a corner (the plane's point moves faster off the face), on a
        // level (n >> ⌊bias⌋) texels across; texels differ by less than 2.
        let finest = f64::from(n >> bias as u32);
        let bound = 2.0 * 2.0 * 0.4 * finest / (steps - 1) as f64;
        let mut steepest = 0.0f64;
        for row in 0..sweeps as usize {
            for k in 1..steps {
                for ch in 0..c as usize {
                    let a = out[((row * steps + k - 1) * c as usize) + ch];
                    let b = out[((row * steps + k) * c as usize) + ch];
                    steepest = steepest.max(f64::from((b - a).abs()));
                }
            }
        }
        eprintln!("{filter:?}: steepest step {steepest:.3e}, bound {bound:.3e}");
        assert!(
            steepest <= bound,
            "{filter:?}: a step of {steepest} across an edge (bound {bound})"
        );
    }
}

/// Every output of every cube mode, forward and backward, hashed against
/// `tests/data/texture-cube-golden.txt` (`TEXTURE_GOLDEN=print` prints it): the same bytes on
/// every run, at 4, 8 and 16 lanes and with GPU workgroup shapes (CI reruns this file in each).
#[test]
fn every_cube_mode_writes_the_golden_bytes() {
    let Some(ctx) = common::gpu() else { return };
    let mut sampler = TextureSampler::new(&ctx).unwrap();
    let mut listing = String::new();
    for filter in FILTERS {
        let inputs = (filter.uses_mips(), filter.uses_mips());
        let case = Case::new(11, [2, 8, 3], None, inputs);
        let c = case.layout.channels as usize;
        let dy: Vec<f32> = (0..case.points() * c)
            .map(|i| ((i % 11) as f32 - 5.0) * 0.1)
            .collect();
        let mode = TexMode::Cube(filter);
        let out = sampler
            .sample(
                &ctx,
                &case.layout,
                mode,
                Levels::Build(&case.tex),
                &case.lookup(),
            )
            .unwrap();
        let g: TextureGrads32 = sampler
            .sample_grad(
                &ctx,
                &case.layout,
                mode,
                Levels::Build(&case.tex),
                &case.lookup(),
                &dy,
            )
            .unwrap();
        for (what, data) in [
            ("out", &out),
            ("grad tex", &g.stack),
            ("grad dir", &g.uv),
            ("grad uv_da", &g.uv_da),
            ("grad bias", &g.bias),
        ] {
            if !data.is_empty() {
                listing.push_str(&format!("{:016x}  cube {filter:?} {what}\n", fnv1a(data)));
            }
        }
    }
    if std::env::var("TEXTURE_GOLDEN").is_ok_and(|v| v == "print") {
        print!("{listing}");
    }
    let golden = include_str!("data/texture-cube-golden.txt");
    assert_eq!(
        listing, golden,
        "the cube kernels' bytes differ from tests/data/texture-cube-golden.txt"
    );
}
