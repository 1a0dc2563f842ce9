//! How a forward's fine pass meets faces and pixels ([`Method`]): every face for every pixel, or
//! the faces binned to each pixel's tile. Below the scene and the stages, which all record by
//! it; [`crate::raster::gpu`] re-exports it.

/// Tile edge (pixels) of [`Method::default`]. Chosen by `softvk bench` on lavapipe; see
/// BENCHMARKS.md.
pub const DEFAULT_TILE: u32 = 8;

/// How the fine pass finds the faces of a pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// SoftRas's own loop: every face for every pixel (the baseline).
    Brute,
    /// Faces binned to `tile × tile`-pixel tiles (a multiple of 8); each pixel visits its tile's.
    Tiled {
        /// Tile edge in pixels.
        tile: u32,
    },
}

impl Default for Method {
    fn default() -> Self {
        Method::Tiled { tile: DEFAULT_TILE }
    }
}
