//! GPU scan and radix sort against their CPU twins, on lavapipe with validation on.

mod common;

use rand::RngExt;
use softvk::primitives::sort::cpu::sort_pairs;
use softvk::primitives::{RadixSort, Scan, scan};

/// Sizes the issue names, plus block (`SCAN_BLOCK` = 8 192) and multi-level boundaries.
const SIZES: &[usize] = &[
    0, 1, 2, 1023, 1024, 1025, 4095, 4096, 4097, 8191, 8192, 8193, 1_048_575, 1_000_000,
];

fn check_scan(scan: &Scan, gpu: &common::Gpu, data: &[u32]) {
    let (gpu_out, gpu_total) = scan.run(gpu, data).expect("GPU scan");
    let (cpu_out, cpu_total) = scan::cpu::exclusive_scan(data);
    assert_eq!(gpu_total, cpu_total, "total of {} elements", data.len());
    if let Some(i) = (0..data.len()).find(|&i| gpu_out[i] != cpu_out[i]) {
        panic!(
            "scan of {} elements differs first at {i}: GPU {} CPU {}",
            data.len(),
            gpu_out[i],
            cpu_out[i]
        );
    }
}

#[test]
fn scan_equals_cpu_twin_on_edge_and_random_sizes() {
    let Some(gpu) = common::gpu() else { return };
    let scan = Scan::new(&gpu).unwrap();
    let mut rng = common::rng(1);
    let mut sizes = SIZES.to_vec();
    sizes.extend((0..6).map(|_| rng.random_range(1..300_000usize)));
    for &n in &sizes {
        let data: Vec<u32> = (0..n).map(|_| rng.random_range(0..1000u32)).collect();
        check_scan(&scan, &gpu, &data);
    }
}

#[test]
fn scan_wraps_like_the_cpu_twin_with_all_bits_set() {
    let Some(gpu) = common::gpu() else { return };
    let scan = Scan::new(&gpu).unwrap();
    for n in [1, 2, 1025, 70_000] {
        check_scan(&scan, &gpu, &vec![u32::MAX; n]);
    }
}

#[test]
fn scan_of_2_pow_26_elements_crosses_binding_chunks() {
    // 2^26 + 3 elements is 256 MiB: more than lavapipe binds at once (128 MiB), three levels.
    let Some(gpu) = common::gpu() else { return };
    let scan = Scan::new(&gpu).unwrap();
    let n = (1usize << 26) + 3;
    let data: Vec<u32> = (0..n as u32)
        .map(|i| i.wrapping_mul(2_654_435_761) >> 28)
        .collect();
    check_scan(&scan, &gpu, &data);
}

fn check_sort(sort: &RadixSort, gpu: &common::Gpu, keys: &[u64], key_bits: u32) {
    let values: Vec<u32> = (0..keys.len() as u32).collect();
    let (gk, gv) = sort.run(gpu, keys, &values, key_bits).expect("GPU sort");
    let (ck, cv) = sort_pairs(keys, &values, key_bits);
    assert_eq!(gk.len(), ck.len());
    if let Some(i) = (0..keys.len()).find(|&i| gk[i] != ck[i] || gv[i] != cv[i]) {
        panic!(
            "sort of {} pairs ({key_bits} bits) differs first at {i}: GPU ({:#x}, {}) CPU ({:#x}, {})",
            keys.len(),
            gk[i],
            gv[i],
            ck[i],
            cv[i]
        );
    }
}

#[test]
fn sort_equals_cpu_twin_on_edge_and_random_sizes() {
    let Some(gpu) = common::gpu() else { return };
    let sort = RadixSort::new(&gpu).unwrap();
    let mut rng = common::rng(2);
    let mut sizes = SIZES.to_vec();
    sizes.extend((0..4).map(|_| rng.random_range(1..200_000usize)));
    for &n in &sizes {
        let keys: Vec<u64> = (0..n).map(|_| rng.random::<u64>()).collect();
        check_sort(&sort, &gpu, &keys, 64);
    }
}

/// Every path of the sort and their boundaries: one workgroup for at most `SMALL_SORT_MAX` pairs
/// (one block, full or partial); up to eight blocks, the scatter sums the digit counts itself;
/// above, a scan dispatch. Odd and even pass counts, a last pass narrower than `RADIX_BITS`, and
/// heavy ties (stability).
#[test]
fn sort_paths_agree_with_the_twin_at_their_boundaries() {
    use softvk::primitives::{SMALL_SORT_MAX, SORT_BLOCK};
    let Some(gpu) = common::gpu() else { return };
    let sort = RadixSort::new(&gpu).unwrap();
    let mut rng = common::rng(6);
    let max = SMALL_SORT_MAX as usize;
    let block = SORT_BLOCK as usize;
    assert_eq!(max, block, "the one-workgroup sort holds one block");
    for n in [
        1,
        5,
        100,
        max - 1,
        max,
        max + 1,
        3 * block,
        8 * block,
        8 * block + 1,
    ] {
        let keys: Vec<u64> = (0..n).map(|_| rng.random::<u64>()).collect();
        for bits in [3, 8, 11, 13, 17] {
            check_sort(&sort, &gpu, &keys, bits);
        }
        let ties: Vec<u64> = (0..n).map(|_| rng.random_range(0..5u64) << 4).collect();
        check_sort(&sort, &gpu, &ties, 7);
    }
}

#[test]
fn sort_handles_keys_with_all_bits_set() {
    let Some(gpu) = common::gpu() else { return };
    let sort = RadixSort::new(&gpu).unwrap();
    let mut rng = common::rng(3);
    // A mix of u64::MAX, 0 and values one bit away from either end.
    let pool = [
        u64::MAX,
        0,
        u64::MAX - 1,
        1,
        1 << 63,
        (1 << 63) - 1,
        u64::from(u32::MAX),
        1 << 32,
    ];
    for n in [1, 2, 1023, 1025, 50_000] {
        let keys: Vec<u64> = (0..n)
            .map(|_| pool[rng.random_range(0..pool.len())])
            .collect();
        check_sort(&sort, &gpu, &keys, 64);
    }
    check_sort(&sort, &gpu, &vec![u64::MAX; 3000], 64);
}

#[test]
fn sort_is_stable_on_heavily_repeated_keys() {
    let Some(gpu) = common::gpu() else { return };
    let sort = RadixSort::new(&gpu).unwrap();
    let mut rng = common::rng(4);
    let n = 300_000;
    // 7 distinct keys: most pairs tie, so any instability would reorder values (= input index).
    let keys: Vec<u64> = (0..n)
        .map(|_| rng.random_range(0..7u64) * 0x0101_0101_0101_0101)
        .collect();
    let values: Vec<u32> = (0..n as u32).collect();
    let (gk, gv) = sort.run(&gpu, &keys, &values, 64).unwrap();
    for i in 1..n {
        assert!(gk[i - 1] <= gk[i], "not sorted at {i}");
        if gk[i - 1] == gk[i] {
            assert!(
                gv[i - 1] < gv[i],
                "equal keys reordered at {i}: stability broken"
            );
        }
    }
}

#[test]
fn sort_by_fewer_key_bits_ignores_the_rest_and_keeps_order() {
    let Some(gpu) = common::gpu() else { return };
    let sort = RadixSort::new(&gpu).unwrap();
    let mut rng = common::rng(5);
    let keys: Vec<u64> = (0..100_000).map(|_| rng.random::<u64>()).collect();
    for bits in [1, 4, 13, 32, 36] {
        check_sort(&sort, &gpu, &keys, bits);
    }
}

/// The exact binning equals its twin, and the guarded binning (count never read on the host)
/// gives the same entries, item slots and ranges at every capacity that holds the count,
/// including exactly the count, with both strategies: per-tile masks (small grids), and the sort
/// (sentinel keys over the whole capacity; a grid over `MASK_MAX_TILES_PER_VIEW` tiles per
/// view), also on a grid whose tile count is a power of two (the sentinel then needs one key bit
/// more); `offsets[items]` holds the total. The same over a window of each grid's tile rows
/// (`TileGrid::window`, what a view too large for one binding is binned in).
#[test]
fn guarded_binning_equals_the_twin_at_any_capacity_that_holds_the_count() {
    use softvk::primitives::binning::{
        self, BinJob, BinStrategy, Binner, Bins, ItemLayout, MASK_MAX_TILES_PER_VIEW, TileGrid,
    };
    let Some(gpu) = common::gpu() else { return };
    let binner = Binner::new(&gpu).unwrap();
    let mut rng = common::rng(7);
    // (width, height, views, items per view, binned by masks): 520×264 is 65×33 tiles of 8,
    // over the masks' limit; 512×512 is 4096 tiles, a power of two. 2 100 items per view make
    // masks of 66 words, whose summaries take three words a tile (the last one partly).
    for (w, h, views, per_view, masks) in [
        (37, 23, 3, 60, true),
        (32, 32, 4, 60, true),
        (40, 24, 2, 2100, true),
        (520, 264, 2, 60, false),
        (512, 512, 1, 60, false),
    ] {
        let image = TileGrid::new(w, h, 8).unwrap();
        assert_eq!(
            image.tiles_per_view() <= MASK_MAX_TILES_PER_VIEW,
            masks,
            "{w}x{h}"
        );
        // The whole grid, and a window of its tile rows (as a view too large for one binding
        // is binned): rows 1 .. rows - 1, whose tiles are numbered from its first row.
        let window = image.window(1, image.tiles_y - 2).unwrap();
        for grid in [image, window] {
            // 520×264's window (65 × 31 tiles) is binned by masks, 512×512's by the sort.
            let masks = grid.tiles_per_view() <= MASK_MAX_TILES_PER_VIEW;
            let n = (per_view * views) as usize;
            // Boxes in pixel-centre coordinates (x, y in about [-1.2, 1.2]), a fifth not binned.
            let mut words = Vec::with_capacity(5 * n);
            let mut boxes = Vec::with_capacity(n);
            for _ in 0..n {
                let (x, y) = (
                    rng.random_range(-1.2..1.2f32),
                    rng.random_range(-1.2..1.2f32),
                );
                let (dx, dy) = (rng.random_range(0.0..0.6f32), rng.random_range(0.0..0.4f32));
                let b = [x, y, x + dx, y + dy];
                let binned = rng.random_range(0..5) != 0;
                words.extend_from_slice(&b);
                words.push(f32::from_bits(u32::from(binned)));
                boxes.push(binned.then_some(b));
            }
            let items = gpu.upload_buffer("boxes", &words).unwrap();
            let job = BinJob {
                grid,
                layout: ItemLayout {
                    stride_words: 5,
                    box_offset: 0,
                    flag_offset: 4,
                    flag_mask: 1,
                },
                items_per_view: per_view,
                views,
                first_item: 0,
            };
            assert_eq!(
                matches!(job.strategy(&gpu), BinStrategy::Masks { .. }),
                masks,
                "{w}x{h}: strategy"
            );
            let twin = binning::cpu::bin(&boxes, per_view, &grid);
            // The exact binning (count read back between two submissions) first.
            let mut exact = Bins::new(&gpu).unwrap();
            let binned = binner.run(&gpu, &mut exact, &items, &job).unwrap();
            assert!(
                binned == twin,
                "{w}x{h}: exact binning differs from the twin"
            );
            let total = u64::from(twin.total);
            let mut bins = Bins::new(&gpu).unwrap();
            bins.reserve(&gpu, &job).unwrap();
            for cap in [total, total + 1, 2 * total + 100] {
                bins.reserve_entry_capacity(&gpu, cap).unwrap();
                assert_eq!(bins.entry_capacity(), cap);
                gpu.submit_and_wait(|rec| {
                    binner.record_count(rec, &bins, items.whole(), &job)?;
                    binner.record_sort_guarded(rec, &bins, items.whole(), &job)
                })
                .unwrap();
                let what = format!(
                    "{w}x{h} rows {}+{}, {views} views, capacity {cap} for {total} entries",
                    grid.first_row, grid.tiles_y
                );
                let offsets: Vec<u32> = gpu.read_buffer(bins.offsets(), 0, n + 1).unwrap();
                assert_eq!(offsets[..n], twin.offsets[..], "{what}");
                assert_eq!(u64::from(offsets[n]), total, "{what}: offsets[items]");
                let t = total as usize;
                if !masks {
                    let keys: Vec<[u32; 2]> =
                        gpu.read_buffer(bins.keys(), 0, cap as usize).unwrap();
                    let tiles: Vec<u32> = keys[..t].iter().map(|k| k[0]).collect();
                    assert_eq!(tiles, twin.tiles, "{what}: sorted tiles");
                    assert!(
                        keys[t..].iter().all(|k| *k == [u32::MAX; 2]),
                        "{what}: sentinels"
                    );
                }
                let slots: Vec<u32> = gpu.read_buffer(bins.entries(), 0, t).unwrap();
                assert_eq!(slots, twin.slots, "{what}: slots");
                let slot_items: Vec<u32> = gpu.read_buffer(bins.entry_items(), 0, t).unwrap();
                assert_eq!(slot_items, twin.slot_items, "{what}: slot items");
                let ranges: Vec<[u32; 2]> = gpu
                    .read_buffer(bins.ranges(), 0, job.tile_count() as usize)
                    .unwrap();
                assert_eq!(ranges, twin.ranges, "{what}: ranges");
            }
        }
    }
}

/// A counted sort (the count in a GPU buffer) sorts exactly the first `count` pairs and leaves
/// the rest where they were, for odd and even pass counts, counts inside, at and past a block
/// boundary, zero, and a count over the capacity (clamped to it).
#[test]
fn counted_sort_sorts_the_count_and_keeps_the_tail() {
    use softvk::primitives::SortScratch;
    use softvk::primitives::sort::{join_key, split_key};
    let Some(gpu) = common::gpu() else { return };
    let sort = RadixSort::new(&gpu).unwrap();
    let mut rng = common::rng(21);
    let cap = 3 * 4096 + 77;
    for (count, key_bits) in [
        (0u32, 8u32),
        (1, 4),
        (4095, 12),
        (4096, 13),
        (9000, 13),
        (cap as u32, 9),
        (u32::MAX, 16),
    ] {
        let keys: Vec<u64> = (0..cap).map(|_| rng.random::<u64>()).collect();
        let values: Vec<u32> = (0..cap as u32).map(|v| v ^ 0x5a5a).collect();
        let words: Vec<[u32; 2]> = keys.iter().map(|&k| split_key(k)).collect();
        let key_buf = gpu.upload_buffer("keys", &words).unwrap();
        let value_buf = gpu.upload_buffer("values", &values).unwrap();
        let count_buf = gpu.upload_buffer("count", &[count]).unwrap();
        let scratch = SortScratch::new(&gpu, cap as u64).unwrap();
        gpu.submit_and_wait(|rec| {
            sort.record_counted(
                rec,
                &scratch,
                &key_buf,
                &value_buf,
                cap as u64,
                count_buf.whole(),
                key_bits,
            )
        })
        .unwrap();
        let got_keys: Vec<u64> = gpu
            .read_buffer::<[u32; 2]>(&key_buf, 0, cap)
            .unwrap()
            .into_iter()
            .map(join_key)
            .collect();
        let got_values: Vec<u32> = gpu.read_buffer(&value_buf, 0, cap).unwrap();
        let c = (count as usize).min(cap);
        let (mut want_keys, mut want_values) = sort_pairs(&keys[..c], &values[..c], key_bits);
        want_keys.extend_from_slice(&keys[c..]);
        want_values.extend_from_slice(&values[c..]);
        assert!(
            got_keys == want_keys,
            "keys, count {count}, {key_bits} bits"
        );
        assert!(
            got_values == want_values,
            "values, count {count}, {key_bits} bits"
        );
    }
}

/// A binning whose worst case (items × tiles) passes 2^32 is not refused: its count is exact
/// (64-bit partial sums where the u32 scan could wrap), whether the real total is small (then
/// the binning equals the twin) or itself past 2^32 (then it is read back exactly, for the
/// caller to bin fewer views at once).
#[test]
fn binning_past_a_32_bit_worst_case_counts_exactly() {
    use softvk::primitives::binning::{self, BinJob, Binner, Bins, ItemLayout, TileGrid};
    let Some(gpu) = common::gpu() else { return };
    let binner = Binner::new(&gpu).unwrap();
    // 4096² in 8-pixel tiles: 262 144 tiles; 20 000 items: a worst case of 5.2e9 entries.
    let grid = TileGrid::new(4096, 4096, 8).unwrap();
    let per_view = 20_000u32;
    let layout = ItemLayout {
        stride_words: 5,
        box_offset: 0,
        flag_offset: 4,
        flag_mask: 1,
    };
    let job = BinJob {
        grid,
        layout,
        items_per_view: per_view,
        views: 1,
        first_item: 0,
    };
    assert!(job.max_entries() > u64::from(u32::MAX));
    let mut rng = common::rng(31);
    // Small boxes (a few pixels) anywhere in the image.
    let mut words = Vec::new();
    let mut boxes = Vec::new();
    for _ in 0..per_view {
        let (x, y) = (
            rng.random_range(-1.0..1.0f32),
            rng.random_range(-1.0..1.0f32),
        );
        let b = [x, y, x + 0.003, y + 0.002];
        words.extend_from_slice(&b);
        words.push(f32::from_bits(1));
        boxes.push(Some(b));
    }
    let items = gpu.upload_buffer("small boxes", &words).unwrap();
    let twin = binning::cpu::bin(&boxes, per_view, &grid);
    let mut bins = Bins::new(&gpu).unwrap();
    let binned = binner.run(&gpu, &mut bins, &items, &job).unwrap();
    assert!(
        binned == twin,
        "small boxes: GPU binning differs from the twin"
    );

    // Every item on every tile: 20 000 × 262 144 = 5 242 880 000 entries, past 2^32.
    let all: Vec<f32> = (0..per_view)
        .flat_map(|_| [-2.0f32, -2.0, 2.0, 2.0, f32::from_bits(1)])
        .collect();
    let items = gpu.upload_buffer("whole boxes", &all).unwrap();
    bins.reserve(&gpu, &job).unwrap();
    gpu.submit_and_wait(|rec| binner.record_count(rec, &bins, items.whole(), &job))
        .unwrap();
    let total = bins.read_total(&gpu).unwrap();
    assert_eq!(total, u64::from(per_view) * grid.tiles_per_view());
    assert!(total > u64::from(u32::MAX));
}

/// 70 000 items in one tile: listing them from a mask would take that tile's invocation past
/// llvmpipe's 65 535 loop iterations (which it ends silently), so the strategy falls back to
/// the sort there; either way the binning equals the twin.
#[test]
fn a_crowded_tile_is_binned_whole_under_the_drivers_loop_cap() {
    use softvk::primitives::binning::{
        self, BinJob, BinStrategy, Binner, Bins, ItemLayout, TileGrid,
    };
    let Some(gpu) = common::gpu() else { return };
    let grid = TileGrid::new(64, 64, 8).unwrap();
    let per_view = 70_000u32;
    let job = BinJob {
        grid,
        layout: ItemLayout {
            stride_words: 4,
            box_offset: 0,
            flag_offset: 0,
            flag_mask: 0,
        },
        items_per_view: per_view,
        views: 1,
        first_item: 0,
    };
    if let Some(limit) = gpu.info().shader_loop_limit() {
        assert!(u64::from(per_view) > limit);
        assert_eq!(job.strategy(&gpu), BinStrategy::Sort);
    }
    // Tiny boxes around the centre of tile (3, 3) (pixels 24..32).
    let b = [-0.2f32, 0.1, -0.19, 0.11];
    let words: Vec<f32> = (0..per_view).flat_map(|_| b).collect();
    let boxes = vec![Some(b); per_view as usize];
    let items = gpu.upload_buffer("crowded boxes", &words).unwrap();
    let twin = binning::cpu::bin(&boxes, per_view, &grid);
    let busiest = twin.ranges.iter().map(|r| r[1] - r[0]).max().unwrap();
    assert_eq!(busiest, per_view, "every item in one tile");
    let binned = Binner::new(&gpu)
        .unwrap()
        .run(&gpu, &mut Bins::new(&gpu).unwrap(), &items, &job)
        .unwrap();
    assert!(
        binned == twin,
        "the crowded tile's binning differs from the twin"
    );
}
