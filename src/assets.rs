//! Where the test meshes (spot, the SoftRas spheres) live: `SOFTVK_ASSETS` if set, else the
//! project's own `assets/` folder (they are checked in, with their licences: a clone alone runs
//! its tests and benchmarks). Only tests, benchmarks and examples read them; the built-in demo
//! generates its own meshes and the default fit template is compiled in.

use std::path::PathBuf;

/// The assets folder: `SOFTVK_ASSETS`, else `assets/` of the source tree this was built from.
pub fn dir() -> PathBuf {
    std::env::var_os("SOFTVK_ASSETS")
        .filter(|v| !v.is_empty())
        .map_or_else(
            || PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/assets")),
            PathBuf::from,
        )
}
