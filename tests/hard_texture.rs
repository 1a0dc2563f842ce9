//! nvdiffrast's `texture` and `texture_construct_mip` on the GPU
//! (`softvk::raster::hard::gpu::texture`) against their f64 twin
//! (`softvk::raster::hard::texture`): in every filter × boundary mode, one and three channels,
//! a shared texture and one per minibatch item, at and between mip levels, with `uv_da`, with a
//! bias and with both, on a stack built here and on one given level by level, for sizes that are
//! not powers of two. `uv` lies on a grid of 1/4096, so f32 takes the texels and fractions f64
//! does, also exactly on texel edges and centres (nearest's jumps, the gradients' kinks, the
//! clamp's edge); lookups within 1e-4 of an integer level, where the two may take different
//! levels, are skipped and counted. The rest are held to bounds measured here, each a multiple
//! of the component's own size (the same sums over |dy| and |texels|) plus a floor. Then: a texel read by more lookups than llvmpipe lets one loop run, and the golden
//! bytes at every lane count and workgroup shape.

mod common;

use common::hard::fnv1a;

use rand::RngExt;
use softvk::raster::hard::gpu::texture::{
    Levels, Lookup, Lookups, TexLayout, TextureGrads32, TextureSampler,
};
use softvk::raster::hard::texture::{
    Boundary, Filter, LevelInput, MipStack, Mode, level_of_detail, sample, sample_backward,
};

const FILTERS: [Filter; 4] = [
    Filter::Nearest,
    Filter::Linear,
    Filter::LinearMipmapNearest,
    Filter::LinearMipmapLinear,
];
const BOUNDARIES: [Boundary; 3] = [Boundary::Wrap, Boundary::Clamp, Boundary::Zero];

/// One case: a texture, its stack in f64 and the lookups.
struct Case {
    layout: TexLayout,
    tex: Vec<f32>,
    stack: MipStack,
    grid: Lookups,
    uv: Vec<f32>,
    uv_da: Option<Vec<f32>>,
    bias: Option<Vec<f32>>,
}

impl Case {
    /// `items` textures of `h × w × c` (levels by `max_mip_level`), lookups `[2, 7, 9]` with
    /// uv in [−0.6, 1.6] (multiples of 1/4096) and footprints spanning the levels.
    fn new(
        seed: u64,
        [items, h, w, c]: [u32; 4],
        max_mip_level: Option<u32>,
        level_inputs: (bool, bool),
    ) -> Self {
        let mut rng = common::rng(seed);
        let layout = TexLayout::with_mips(items, h, w, c, max_mip_level).unwrap();
        let n0 = layout.level_texels(0) as usize * c as usize;
        let tex: Vec<f32> = (0..n0).map(|_| rng.random_range(-1.0..1.0)).collect();
        let stack = MipStack::base(
            items as usize,
            h as usize,
            w as usize,
            c as usize,
            tex.iter().map(|&v| f64::from(v)).collect(),
        )
        .unwrap()
        .build(max_mip_level)
        .unwrap();
        assert_eq!(stack.levels.len(), layout.levels as usize);
        let grid = Lookups {
            batch: 2,
            height: 7,
            width: 9,
            uv_da: level_inputs.0,
            bias: level_inputs.1,
        };
        let points = grid.points() as usize;
        // On a grid of 1/4096: u·w and v·h are exact in f32 for these sizes, so f32 and f64
        // take the same texels, the same fractions and the same weights, and the bounds below
        // hold the arithmetic after them.
        let uv = (0..2 * points)
            .map(|_| (rng.random_range(-0.6f32..1.6) * 4096.0).round() / 4096.0)
            .collect();
        // Footprints from a tenth of a texel to the whole texture, anisotropic.
        let uv_da = level_inputs.0.then(|| {
            (0..points)
                .flat_map(|_| {
                    let scale = 2f32.powf(rng.random_range(-3.5..1.0)) / w.max(h) as f32;
                    let a: [f32; 4] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
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
            uv,
            uv_da,
            bias,
        }
    }

    fn lookup(&self) -> Lookup<'_> {
        Lookup {
            grid: self.grid,
            uv: &self.uv,
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

    fn uv_at(&self, i: usize) -> [f64; 2] {
        [f64::from(self.uv[2 * i]), f64::from(self.uv[2 * i + 1])]
    }

    fn level_at(&self, i: usize) -> LevelInput {
        LevelInput {
            uv_da: self
                .uv_da
                .as_ref()
                .map(|d| std::array::from_fn(|k| f64::from(d[4 * i + k]))),
            bias: self.bias.as_ref().map(|b| f64::from(b[i])),
        }
    }

    /// The stack as the kernels lay it out, in f32: every level of the twin's.
    fn stack_f32(&self) -> Vec<f32> {
        self.stack
            .levels
            .iter()
            .flat_map(|l| l.texels.iter().map(|&v| v as f32))
            .collect()
    }

    /// Whether lookup `i`'s level lies within `margin` of an integer, where f32 and f64 may
    /// take different levels (linear-mipmap-nearest jumps there; linear-mipmap-linear's
    /// gradients kink). Texels and fractions are exact (uv's grid), so nothing else is skipped.
    fn near_integer_level(&self, i: usize, mode: Mode, margin: f64) -> bool {
        if !mode.filter.uses_mips() {
            return false;
        }
        let base = &self.stack.levels[0];
        let raw = level_of_detail(self.level_at(i), base.width, base.height);
        let top = self.stack.max_level() as f64;
        (raw - raw.round()).abs() < margin && raw > -margin && raw < top + margin
    }
}

fn mode_name(mode: Mode) -> String {
    format!("{:?}/{:?}", mode.filter, mode.boundary)
}

/// The cases every comparison runs: (name, case, whether the stack is given level by level).
fn cases(filter: Filter) -> Vec<(String, Case)> {
    let level_inputs: Vec<(bool, bool)> = if filter.uses_mips() {
        vec![(true, false), (false, true), (true, true)]
    } else {
        vec![(false, false)]
    };
    let mut out = Vec::new();
    for (k, &inputs) in level_inputs.iter().enumerate() {
        // Not a power of two: 20 × 12 halves twice (10 × 6, 5 × 3), then 5 is odd.
        let seed = 17 * k as u64;
        out.push((
            format!("shared 12x20x3, levels {inputs:?}"),
            Case::new(seed, [1, 12, 20, 3], Some(2), inputs),
        ));
        // A full stack down to 1 × 1 through the 2 × 1 levels, one texture per item.
        out.push((
            format!("per-item 4x16x1, levels {inputs:?}"),
            Case::new(seed + 1, [2, 4, 16, 1], None, inputs),
        ));
    }
    if !filter.uses_mips() {
        out.push((
            "shared 5x7x2".into(),
            Case::new(99, [1, 5, 7, 2], Some(0), (false, false)),
        ));
    }
    out
}

#[test]
fn the_mip_stack_matches_the_twin() {
    let Some(ctx) = common::gpu() else { return };
    let mut sampler = TextureSampler::new(&ctx).unwrap();
    for (dims, max) in [
        ([1, 12, 20, 3], Some(2)),
        ([2, 4, 16, 1], None),
        ([1, 1, 8, 2], None),
    ] {
        let case = Case::new(5, dims, max, (false, false));
        let gpu = sampler
            .construct_mip(&ctx, &case.layout, &case.tex)
            .unwrap();
        let twin = case.stack_f32();
        assert_eq!(gpu.len(), twin.len());
        for (i, (g, t)) in gpu.iter().zip(&twin).enumerate() {
            // Four f32 additions and an exact scale: a few ulps of the inputs (≤ 1).
            assert!(
                (g - t).abs() <= 3e-7,
                "{dims:?} float {i}: GPU {g} twin {t}"
            );
        }
    }
    // Odd extents: the same error as the twin's.
    let err = TexLayout::with_mips(1, 12, 20, 3, None).unwrap_err();
    assert!(err.to_string().contains("odd extent"), "{err}");
}

#[test]
fn every_mode_samples_as_the_twin() {
    let Some(ctx) = common::gpu() else { return };
    let mut sampler = TextureSampler::new(&ctx).unwrap();
    let (mut checked, mut skipped) = (0usize, 0usize);
    let mut worst = 0.0f64;
    for filter in FILTERS {
        for boundary in BOUNDARIES {
            let mode = Mode { filter, boundary };
            for (name, case) in cases(filter) {
                let stack = case.stack_f32();
                let built = sampler
                    .sample(
                        &ctx,
                        &case.layout,
                        mode.into(),
                        Levels::Build(&case.tex),
                        &case.lookup(),
                    )
                    .unwrap();
                let given = sampler
                    .sample(
                        &ctx,
                        &case.layout,
                        mode.into(),
                        Levels::Given(&stack),
                        &case.lookup(),
                    )
                    .unwrap();
                let c = case.layout.channels as usize;
                for i in 0..case.points() {
                    if case.near_integer_level(i, mode, 1e-4) {
                        skipped += 1;
                        continue;
                    }
                    checked += 1;
                    let twin = sample(
                        &case.stack,
                        case.item(i),
                        case.uv_at(i),
                        case.level_at(i),
                        mode,
                    );
                    for k in 0..c {
                        for (what, out) in [("built", &built), ("given", &given)] {
                            let e = (f64::from(out[i * c + k]) - twin[k]).abs();
                            worst = worst.max(e);
                            assert!(
                                e <= 4e-7,
                                "{} {name} ({what} stack): lookup {i} channel {k}: GPU {} \
                                 twin {}",
                                mode_name(mode),
                                out[i * c + k],
                                twin[k]
                            );
                        }
                    }
                }
            }
        }
    }
    eprintln!("forward: {checked} lookups checked, {skipped} skipped, worst {worst:.2e}");
    assert!(
        skipped * 20 < checked,
        "{checked} checked, {skipped} skipped"
    );
}

/// The twin's backward for one case: every level's texel gradients (before the pyramid) and
/// the lookups' own, and the same with every |dy| and |texel| (the sizes the bounds scale by).
struct TwinGrads {
    levels: Vec<Vec<f64>>,
    uv: Vec<[f64; 2]>,
    uv_da: Vec<[f64; 4]>,
    bias: Vec<f64>,
}

fn twin_grads(case: &Case, mode: Mode, dy: &[f32], stack: &MipStack) -> TwinGrads {
    let c = case.layout.channels as usize;
    let mut levels = stack.zero_grads();
    let mut g = TwinGrads {
        levels: Vec::new(),
        uv: Vec::new(),
        uv_da: Vec::new(),
        bias: Vec::new(),
    };
    for i in 0..case.points() {
        let d: Vec<f64> = dy[i * c..(i + 1) * c]
            .iter()
            .map(|&v| f64::from(v))
            .collect();
        let p = sample_backward(
            stack,
            case.item(i),
            case.uv_at(i),
            case.level_at(i),
            mode,
            &d,
            &mut levels,
        );
        g.uv.push(p.uv);
        g.uv_da.push(p.uv_da);
        g.bias.push(p.bias);
    }
    g.levels = levels;
    g
}

#[test]
fn every_gradient_matches_the_twin() {
    let Some(ctx) = common::gpu() else { return };
    let mut sampler = TextureSampler::new(&ctx).unwrap();
    let (mut checked, mut skipped) = (0usize, 0usize);
    let mut worst = [0.0f64; 4];
    for filter in FILTERS {
        for boundary in BOUNDARIES {
            let mode = Mode { filter, boundary };
            for (name, case) in cases(filter) {
                let c = case.layout.channels as usize;
                let mut rng = common::rng(3);
                let dy: Vec<f32> = (0..case.points() * c)
                    .map(|_| rng.random_range(-1.0..1.0))
                    .collect();
                let stack = case.stack_f32();
                let what = format!("{} {name}", mode_name(mode));
                let twin = twin_grads(&case, mode, &dy, &case.stack);
                // Sizes: the same sums over |dy| and |texels|.
                let abs_dy: Vec<f32> = dy.iter().map(|v| v.abs()).collect();
                let mut abs_stack = case.stack.clone();
                for l in &mut abs_stack.levels {
                    l.texels.iter_mut().for_each(|v| *v = v.abs());
                }
                let size = twin_grads(&case, mode, &abs_dy, &abs_stack);
                let given = sampler
                    .sample_grad(
                        &ctx,
                        &case.layout,
                        mode.into(),
                        Levels::Given(&stack),
                        &case.lookup(),
                        &dy,
                    )
                    .unwrap();
                let built = sampler
                    .sample_grad(
                        &ctx,
                        &case.layout,
                        mode.into(),
                        Levels::Build(&case.tex),
                        &case.lookup(),
                        &dy,
                    )
                    .unwrap();
                // The lookups' own gradients, away from kinks.
                for i in 0..case.points() {
                    if case.near_integer_level(i, mode, 1e-4) {
                        skipped += 1;
                        continue;
                    }
                    checked += 1;
                    for g in [&given, &built] {
                        for k in 0..2 {
                            let e = (f64::from(g.uv[2 * i + k]) - twin.uv[i][k]).abs();
                            let s = size.uv[i][k].abs() + 1.0;
                            worst[0] = worst[0].max(e / s);
                            assert!(
                                e <= 1.5e-5 * s,
                                "{what}: d/duv[{i}][{k}] GPU {} twin {}",
                                g.uv[2 * i + k],
                                twin.uv[i][k]
                            );
                        }
                        if case.grid.uv_da {
                            for k in 0..4 {
                                let e = (f64::from(g.uv_da[4 * i + k]) - twin.uv_da[i][k]).abs();
                                let s = twin.uv_da[i][k].abs() + 1.0;
                                worst[1] = worst[1].max(e / s);
                                assert!(
                                    e <= 1e-5 * s,
                                    "{what}: d/duv_da[{i}][{k}] GPU {} twin {}",
                                    g.uv_da[4 * i + k],
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
                // The texels': every level of the given stack on its own, and the built one's
                // carried into its base.
                let mut at = 0;
                let mut carried = twin.levels.clone();
                let base_grad = case.stack.pyramid_backward(std::mem::take(&mut carried));
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
    }
    eprintln!(
        "backward: {checked} lookups checked, {skipped} skipped; worst relative uv {:.2e}, \
         uv_da {:.2e}, bias {:.2e}, texels {:.2e}",
        worst[0], worst[1], worst[2], worst[3]
    );
    assert!(
        skipped * 10 < checked,
        "{checked} checked, {skipped} skipped"
    );
}

/// One texel read by 102 400 entries (a 1 × 1 texture, every tap of 160 × 160 lookups): more
/// than llvmpipe lets one loop run (65 535), so a single loop over the texel's entries would
/// drop some. Its gradient is the sum of every dy, the taps' weights summing to 1.
#[test]
fn a_texel_read_by_more_lookups_than_one_loop_may_run_gets_every_one() {
    let Some(ctx) = common::gpu() else { return };
    let mut sampler = TextureSampler::new(&ctx).unwrap();
    let layout = TexLayout::new(1, 1, 1, 1, 1).unwrap();
    let grid = Lookups {
        batch: 1,
        height: 160,
        width: 160,
        uv_da: false,
        bias: false,
    };
    let points = grid.points() as usize;
    let uv: Vec<f32> = (0..2 * points).map(|i| (i % 13) as f32 / 13.0).collect();
    let dy: Vec<f32> = (0..points).map(|i| 1.0 + (i % 5) as f32).collect();
    let lookup = Lookup {
        grid,
        uv: &uv,
        uv_da: None,
        bias: None,
    };
    let mode = Mode {
        filter: Filter::Linear,
        boundary: Boundary::Wrap,
    };
    let TextureGrads32 { stack, .. } = sampler
        .sample_grad(
            &ctx,
            &layout,
            mode.into(),
            Levels::Given(&[0.5]),
            &lookup,
            &dy,
        )
        .unwrap();
    let want: f64 = dy.iter().map(|&v| f64::from(v)).sum();
    assert!(
        (f64::from(stack[0]) - want).abs() <= 1e-6 * want,
        "GPU {} want {want}",
        stack[0]
    );
}

/// Every output of every mode, forward and backward, hashed: the same bytes on every run and,
/// since no sum's order depends on the lanes or the workgroups, at 4, 8 and 16 lanes and with
/// GPU workgroup shapes (CI reruns this file in each), against
/// `tests/data/texture-golden.txt`. A change that alters an output on purpose regenerates that
/// list (`TEXTURE_GOLDEN=print` prints it) and says why in its commit.
#[test]
fn every_mode_writes_the_golden_bytes() {
    let Some(ctx) = common::gpu() else { return };
    let mut sampler = TextureSampler::new(&ctx).unwrap();
    let mut listing = String::new();
    for filter in FILTERS {
        for boundary in BOUNDARIES {
            let mode = Mode { filter, boundary };
            let inputs = (filter.uses_mips(), filter.uses_mips());
            let case = Case::new(11, [2, 8, 16, 3], None, inputs);
            let c = case.layout.channels as usize;
            let dy: Vec<f32> = (0..case.points() * c)
                .map(|i| ((i % 11) as f32 - 5.0) * 0.1)
                .collect();
            let out = sampler
                .sample(
                    &ctx,
                    &case.layout,
                    mode.into(),
                    Levels::Build(&case.tex),
                    &case.lookup(),
                )
                .unwrap();
            let g = sampler
                .sample_grad(
                    &ctx,
                    &case.layout,
                    mode.into(),
                    Levels::Build(&case.tex),
                    &case.lookup(),
                    &dy,
                )
                .unwrap();
            let name = mode_name(mode);
            for (what, data) in [
                ("out", &out),
                ("grad tex", &g.stack),
                ("grad uv", &g.uv),
                ("grad uv_da", &g.uv_da),
                ("grad bias", &g.bias),
            ] {
                if !data.is_empty() {
                    listing.push_str(&format!("{:016x}  {name} {what}\n", fnv1a(data)));
                }
            }
        }
    }
    if std::env::var("TEXTURE_GOLDEN").is_ok_and(|v| v == "print") {
        print!("{listing}");
    }
    let golden = include_str!("data/texture-golden.txt");
    assert_eq!(
        listing, golden,
        "the texture kernels' bytes differ from tests/data/texture-golden.txt"
    );
}
