//! GPU scan and radix sort against their CPU twins, on lavapipe with validation on.

mod common;

use rand::RngExt;
use softvk::primitives::sort::cpu::sort_pairs;
use softvk::primitives::{RadixSort, Scan, scan};

/// Sizes the issue names, plus block and multi-level boundaries.
const SIZES: &[usize] = &[
    0, 1, 2, 1023, 1024, 1025, 4095, 4096, 4097, 1_048_575, 1_000_000,
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
