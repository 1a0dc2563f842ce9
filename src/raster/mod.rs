//! Soft rasterization (SPEC §2). For now the f64 CPU twin ([`reference`]); the tiled GPU forward
//! (face setup → binning → fine raster) is built next and tested against it.

pub mod reference;
