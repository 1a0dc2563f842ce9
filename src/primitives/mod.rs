//! GPU building blocks the binning stages stand on: exclusive prefix sum and stable radix sort.
//! Each has a CPU twin (`cpu` submodule) that tests use as the oracle.

pub mod scan;
pub mod sort;

pub use scan::{Scan, ScanScratch, SCAN_BLOCK};
pub use sort::{RadixSort, SortScratch, RADIX_BITS, SORT_BLOCK};
