//! How a forward's fine pass meets faces and pixels ([`Method`]): every face for every pixel, or
//! the faces binned to each pixel's tile. Below the scene and the stages, which all record by
//! it; [`crate::raster::gpu`] re-exports it.

use crate::error::{Error, Result};

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

impl Method {
    /// [`Error::Input`] unless `tile` is a tile edge the tiled kernels support: a multiple of
    /// their 8×8 workgroup block, from 8 to 256. The renderer checks every tiled run with it; a
    /// command checks its user's tile size with it before any work.
    pub fn check_tile(tile: u32) -> Result<()> {
        if tile == 0 || tile % 8 != 0 || tile > 256 {
            return Err(Error::Input(format!(
                "tile size {tile}: must be a multiple of 8 between 8 and 256"
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_sizes_are_multiples_of_the_block() {
        for t in [8, 16, 32, 64, 256] {
            assert!(Method::check_tile(t).is_ok());
        }
        for t in [0, 4, 12, 264] {
            assert!(Method::check_tile(t).is_err());
        }
    }
}
