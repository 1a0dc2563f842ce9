//! Scan and radix-sort throughput. Each case is recorded once; an iteration is one submit + wait.
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

criterion_group!(benches, scan, sort);
criterion_main!(benches);
