//! Where the shared test meshes (spot, spheres) live: `SOFTVK_ASSETS`, falling back to
//! `../shared/assets` (the layout of a checkout beside the project's shared folder). Only tests
//! and benchmarks read them; the built-in demo generates its own meshes.

use std::path::PathBuf;

/// The assets folder.
pub fn dir() -> PathBuf {
    std::env::var_os("SOFTVK_ASSETS")
        .filter(|v| !v.is_empty())
        .map_or_else(|| PathBuf::from("../shared/assets"), PathBuf::from)
}
