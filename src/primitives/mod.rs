//! GPU building blocks the binning stages stand on: exclusive prefix sum and stable radix sort.
//! Each has a CPU twin (`cpu` submodule) that tests use as the oracle.

pub mod scan;
pub mod sort;

pub use scan::{SCAN_BLOCK, Scan, ScanScratch};
pub use sort::{RADIX_BITS, RadixSort, SORT_BLOCK, SortScratch};
