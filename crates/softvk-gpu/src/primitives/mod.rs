//! GPU building blocks: exclusive prefix sum, stable radix sort, and the tiled binning built on
//! them. Each has a CPU twin (`cpu` submodule) that tests use as the oracle.

pub mod binning;
pub mod scan;
pub mod sort;
pub mod sum;

pub use binning::{BinJob, Binner, Bins, ItemLayout, TileGrid};
pub use scan::{SCAN_BLOCK, Scan, ScanScratch};
pub use sort::{RADIX_BITS, RadixSort, SMALL_SORT_MAX, SORT_BLOCK, SortScratch};
