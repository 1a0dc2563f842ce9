//! Scan and radix-sort throughput, and nvdiffrast's `texture` (forward with its mip levels built,
//! and backward, linear-mipmap-linear on a 1024² RGB texture) per lookup. Each case is recorded
//! once; an iteration is one submit + wait.
//! Two series per case: `wall` (submit to fence, host clock) and `gpu` (GPU timestamps around the
//! work), both as elements/s through criterion's throughput.
//!
//! Run: `cargo bench --bench primitives` (device from `SOFTVK_DEVICE`, as everywhere).

mod common;

use std::time::Duration;

use common::{context, time};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use softvk::gpu::Timer;
use softvk::primitives::sort::split_key;
use softvk::primitives::{RadixSort, Scan, ScanScratch, SortScratch};

fn scan(c: &mut Criterion) {
    let ctx = context();
    let scan = Scan::new(&ctx).unwrap();
    let mut group = c.benchmark_group(format!("scan/{}", ctx.info().name));
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(3));
    for log2 in [20u32, 24] {
        let n = 1u64 << log2;
        let data: Vec<u32> = (0..n as u32).map(|i| i & 7).collect();
        let buffer = ctx.upload_buffer("bench scan", &data).unwrap();
        let scratch = ScanScratch::new(&ctx, n).unwrap();
        let mut timer = Timer::new(&ctx, 1).unwrap();
        let recorded = ctx
            .record(Some(&mut timer), |rec| {
                rec.pass("scan", |rec| {
                    scan.record(rec, &scratch, buffer.whole(), buffer.whole(), n)
                })
            })
            .unwrap();
        group.throughput(Throughput::Elements(n));
        for (clock, gpu_clock) in [("wall", false), ("gpu", true)] {
            group.bench_function(BenchmarkId::new(clock, format!("2^{log2}")), |b| {
                b.iter_custom(|iters| time(&recorded, &timer, &ctx, gpu_clock, iters))
            });
        }
    }
    group.finish();
}

fn sort(c: &mut Criterion) {
    let ctx = context();
    let sort = RadixSort::new(&ctx).unwrap();
    let mut group = c.benchmark_group(format!("sort/{}", ctx.info().name));
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(5));
    let n = 1u64 << 20;
    // Sorting sorted data would flatter nothing here (every pass moves every pair), but use
    // scrambled keys anyway so the scatter's access pattern is realistic.
    let keys: Vec<[u32; 2]> = (0..n)
        .map(|i| split_key(i.wrapping_mul(0x9e37_79b9_7f4a_7c15)))
        .collect();
    let values: Vec<u32> = (0..n as u32).collect();
    let key_buf = ctx.upload_buffer("bench sort keys", &keys).unwrap();
    let value_buf = ctx.upload_buffer("bench sort values", &values).unwrap();
    let scratch = SortScratch::new(&ctx, n).unwrap();
    group.throughput(Throughput::Elements(n));
    for key_bits in [32u32, 64] {
        let mut timer = Timer::new(&ctx, 1).unwrap();
        // Sorting in place re-sorts sorted data after the first iteration; the work per pass is
        // the same whatever the order (count, scan, scatter every pair).
        let recorded = ctx
            .record(Some(&mut timer), |rec| {
                rec.pass("sort", |rec| {
                    sort.record(rec, &scratch, &key_buf, &value_buf, n, key_bits)
                })
            })
            .unwrap();
        for (clock, gpu_clock) in [("wall", false), ("gpu", true)] {
            group.bench_function(
                BenchmarkId::new(clock, format!("2^20 x {key_bits}-bit keys")),
                |b| b.iter_custom(|iters| time(&recorded, &timer, &ctx, gpu_clock, iters)),
            );
        }
    }
    group.finish();
}

/// `texture`, linear-mipmap-linear: the forward (the mip levels built, then the lookups) and
/// the backward (after its own mip levels), per lookup, at 512² and 1024² lookups. 2D: a 1024²
/// RGB texture with wrap, a slightly rotated grid 1.5 turns of the texture across (three
/// texels a pixel at 512²: λ ≈ 1.6; λ ≈ 0.6 at 1024²). Cube: a cube map of 512² RGB faces (1.5
/// times the 2D texels), the whole sphere as a panorama with its pixel derivatives as `uv_da`
/// (λ ≈ 2 along the equator at 512², 1 at 1024²).
fn texture(c: &mut Criterion) {
    use softvk::gpu::MemoryKind;
    use softvk::raster::hard::gpu::texture::{
        Lookups, TexLayout, TexMode, TextureGradOutputs, TextureInputs, TextureSampler,
    };
    use softvk::raster::hard::texture::{Boundary, Filter, Mode};
    let ctx = context();
    let mut sampler = TextureSampler::new(&ctx).unwrap();
    let mut group = c.benchmark_group(format!("texture/{}", ctx.info().name));
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(4));
    let flat = TexMode::Flat(Mode {
        filter: Filter::LinearMipmapLinear,
        boundary: Boundary::Wrap,
    });
    let cube = TexMode::Cube(Filter::LinearMipmapLinear);
    for mode in [flat, cube] {
        let (layout, kind) = if mode == flat {
            (TexLayout::with_mips(1, 1024, 1024, 3, None).unwrap(), "")
        } else {
            (TexLayout::with_mips(6, 512, 512, 3, None).unwrap(), "cube ")
        };
        let mut tex = vec![0.0f32; layout.floats() as usize];
        for (i, v) in tex
            .iter_mut()
            .enumerate()
            .take(layout.level_texels(0) as usize * 3)
        {
            *v = ((i as u32).wrapping_mul(2_654_435_761) >> 8) as f32 / 16_777_216.0;
        }
        let stack = ctx.upload_buffer("bench texture stack", &tex).unwrap();
        for side in [512u32, 1024] {
            let grid = Lookups {
                batch: 1,
                height: side,
                width: side,
                uv_da: true,
                bias: false,
            };
            let n = grid.points();
            let (uv, da) = if mode == flat {
                flat_lookups(side)
            } else {
                cube_lookups(side)
            };
            let uv = ctx.upload_buffer("bench uv", &uv).unwrap();
            let da = ctx.upload_buffer("bench uv_da", &da).unwrap();
            let dy = ctx
                .upload_buffer("bench dy", &vec![1e-3f32; 3 * n as usize])
                .unwrap();
            let out = ctx
                .create_buffer("bench out", 12 * n, MemoryKind::Device)
                .unwrap();
            let g_stack = ctx
                .create_buffer("bench grad stack", 4 * layout.floats(), MemoryKind::Device)
                .unwrap();
            let g_uv = ctx
                .create_buffer(
                    "bench grad uv",
                    4 * mode.uv_floats() * n,
                    MemoryKind::Device,
                )
                .unwrap();
            let g_da = ctx
                .create_buffer(
                    "bench grad uv_da",
                    4 * mode.uv_da_floats() * n,
                    MemoryKind::Device,
                )
                .unwrap();
            let inputs = TextureInputs {
                stack: stack.whole(),
                uv: uv.whole(),
                uv_da: Some(da.whole()),
                bias: None,
            };
            group.throughput(Throughput::Elements(n));
            for backward in [false, true] {
                let mut timer = Timer::new(&ctx, 8).unwrap();
                let recorded = ctx
                    .record(Some(&mut timer), |rec| {
                        sampler.record_construct_mip(rec, &layout, stack.whole())?;
                        if backward {
                            sampler.record_sample_grad(
                                rec,
                                &layout,
                                mode,
                                &grid,
                                inputs,
                                dy.whole(),
                                TextureGradOutputs {
                                    stack: g_stack.whole(),
                                    uv: g_uv.whole(),
                                    uv_da: Some(g_da.whole()),
                                    bias: None,
                                },
                                true,
                            )
                        } else {
                            sampler.record_sample(rec, &layout, mode, &grid, inputs, out.whole())
                        }
                    })
                    .unwrap();
                let what = if backward { "backward" } else { "forward" };
                for (clock, gpu_clock) in [("wall", false), ("gpu", true)] {
                    group.bench_function(
                        BenchmarkId::new(clock, format!("{kind}{what} {side}² lookups")),
                        |b| b.iter_custom(|iters| time(&recorded, &timer, &ctx, gpu_clock, iters)),
                    );
                }
            }
        }
    }
    group.finish();
}

/// The 2D bench's `uv` and `uv_da` on a `side²` grid.
fn flat_lookups(side: u32) -> (Vec<f32>, Vec<f32>) {
    let k = 1.5 / f64::from(side);
    let (mut uv, mut da) = (Vec::new(), Vec::new());
    for y in 0..side {
        for x in 0..side {
            let (fx, fy) = (f64::from(x) + 0.5, f64::from(y) + 0.5);
            uv.extend([(k * (fx + 0.1 * fy)) as f32, (k * (fy - 0.1 * fx)) as f32]);
            da.extend([k as f32, (0.1 * k) as f32, (-0.1 * k) as f32, k as f32]);
        }
    }
    (uv, da)
}

/// The cube bench's directions and their pixel derivatives on a `side²` grid: the whole
/// sphere by longitude across and latitude down (an environment map's panorama), every face
/// read, about `4 · 512 / side` texels a pixel along the equator.
fn cube_lookups(side: u32) -> (Vec<f32>, Vec<f32>) {
    use std::f64::consts::PI;
    let n = f64::from(side);
    let (mut dir, mut da) = (Vec::new(), Vec::new());
    for y in 0..side {
        for x in 0..side {
            let phi = 2.0 * PI * (f64::from(x) + 0.5) / n;
            let theta = PI * (f64::from(y) + 0.5) / n - 0.5 * PI;
            let (sp, cp, st, ct) = (phi.sin(), phi.cos(), theta.sin(), theta.cos());
            dir.extend([ct * sp, st, ct * cp].map(|v| v as f32));
            let (kx, ky) = (2.0 * PI / n, PI / n);
            let d_phi = [ct * cp, 0.0, -ct * sp].map(|v| v * kx);
            let d_theta = [-st * sp, ct, -st * cp].map(|v| v * ky);
            da.extend((0..3).flat_map(|k| [d_phi[k] as f32, d_theta[k] as f32]));
        }
    }
    (dir, da)
}

criterion_group!(benches, scan, sort, texture);
criterion_main!(benches);
