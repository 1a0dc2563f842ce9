//! PyTorch3D's mesh rasterizer (`pytorch3d.renderer.mesh.rasterize_meshes`) on softvk: the K
//! nearest faces of every pixel (`pix_to_face`, `zbuf`, `bary_coords`, `dists`, PyTorch3D's
//! `Fragments`) and the backward of those outputs to the face vertices, on the GPU
//! ([`gpu::FragmentRasterizer`]: tiled, exact binning, deterministic) and as the f64 CPU twin
//! ([`reference`](mod@reference)).
//!
//! The contract, from PyTorch3D's own CPU code (`csrc/rasterize_meshes/rasterize_meshes_cpu.cpp`
//! and `csrc/utils/geometry_utils.h`), which the kernels follow operation for operation in f32
//! and the twin in f64:
//!
//! - **Screen space** is PyTorch3D's NDC: faces arrive projected, `(x, y, z)` with +X left, +Y up
//!   and the shorter image side spanning [-1, 1]. Output row `r` (0 at the top), column `c` (0 at
//!   the left) samples `(x, y) = (ndc(W − 1 − c, W, H), ndc(H − 1 − r, H, W))`, with
//!   `ndc(i, S1, S2) = −R/2 + (R i + R/2) / S1`, `R = 2 S1 / S2` when `S1 > S2`, else 2
//!   ([`pixel_ndc`]).
//! - **A face is skipped** when its signed area `(v0 − v1) × (v2 − v1)` is within 1e-8 of 0,
//!   when it is a back face (area < 0) and `cull_backfaces`, when any vertex has `z < 1e-8`, and
//!   at a pixel outside its bounding box grown by √`blur_radius`. A coordinate that is not
//!   finite (PyTorch3D's arithmetic makes NaN fragments of the face) is refused by the host
//!   entry points ([`check_finite`]); the kernels, which may read an engine's buffers, skip
//!   such a face.
//! - **At a pixel**: the barycentrics `w_k = e_k / (area + 1e-8)` (the edge functions); with
//!   `perspective_correct`, `w_k z_{k+1} z_{k+2} / Σ` (Σ at least 1e-8); with
//!   `clip_barycentric_coords`, clamped at 0 and divided by their sum (at least 1e-5). The depth
//!   is `z = Σ w̃_k z_k` with the clipped ones (the face is skipped where it is negative). `dists`
//!   is the squared distance to the nearest edge (segment), negative when the pixel is inside
//!   (every unclipped barycentric > 0); outside, the face counts only when that distance is below
//!   `blur_radius` — a squared NDC distance, as PyTorch3D compares it.
//! - **Which K**: the faces of the pixel's mesh, ordered by `(z, face index)`: the nearest first,
//!   equal depths by the lower packed index (PyTorch3D keeps a deque sorted by the tuples
//!   `(z, f, ...)` and drops its last past K). Slots past the faces found hold `pix_to_face` −1
//!   and −1 in `zbuf`, `dists` and every barycentric.
//! - **Faces cut at the near plane.** PyTorch3D's `z_clip_value` and `cull_to_frustum` are its
//!   Python (`clip_faces`) before the rasterizer and after it: a face partly behind the plane
//!   becomes one or two new faces, and `neighbors[f]` names the other half of a face cut in
//!   two. At a pixel, such a half replaces its other half in the list when it is nearer to the
//!   pixel (squared edge distance) and is not added beside it; this is the one rule that depends
//!   on the order faces are visited in, the packed order in the twin, PyTorch3D and the kernels.
//! - **The backward** is PyTorch3D's `RasterizeMeshesBackwardCpu`: per kept (pixel, face), the
//!   upstream `dists` gradient through the nearest edge's point-segment distance (the nearest point
//!   held fixed, the envelope theorem; sign flipped inside), the `zbuf` gradient to the
//!   barycentrics (`z_k`) and to the vertex depths (`w̃_k`), the barycentrics' through the clip and
//!   the perspective correction (which also reaches the depths) to the edge functions and area.
//!   On the GPU it is summed per (face, tile) in pixel order and then per face in tile order,
//!   with no float atomics: the same bits on every run.

pub mod gpu;
pub mod reference;

pub use reference::{Fragments, pixel_ndc, pixel_point, rasterize, rasterize_grad};

use crate::error::{Error, Result};

/// Checks a batch as PyTorch3D packs it: mesh `n` owns faces `[first, first + count)` of
/// `face_count`, the ranges in increasing order and not overlapping.
pub fn check_meshes(face_count: usize, meshes: &[(usize, usize)]) -> Result<()> {
    let mut end = 0usize;
    for (n, &(first, count)) in meshes.iter().enumerate() {
        if first < end || first.saturating_add(count) > face_count {
            return Err(Error::Input(format!(
                "fragment rasterizer: mesh {n}'s faces [{first}, {}) overlap the previous \
                 mesh's or pass the {face_count} faces",
                first.saturating_add(count)
            )));
        }
        end = first + count;
    }
    Ok(())
}

/// Refuses face vertices (nine per face) with a coordinate that is not finite: PyTorch3D's
/// arithmetic makes NaN fragments of such a face, which no caller means to get.
pub fn check_finite<T: Copy + Into<f64>>(face_verts: &[T]) -> Result<()> {
    match face_verts.iter().position(|&c| !c.into().is_finite()) {
        None => Ok(()),
        Some(i) => Err(Error::Input(format!(
            "fragment rasterizer: face {} has a coordinate that is not finite ({})",
            i / 9,
            face_verts[i].into()
        ))),
    }
}

/// Checks a forward's `pix_to_face` for a backward over `face_count` faces.
pub fn check_pix_to_face(pix_to_face: &[i64], face_count: usize) -> Result<()> {
    match pix_to_face
        .iter()
        .find(|&&f| f < -1 || f >= face_count as i64)
    {
        None => Ok(()),
        Some(bad) => Err(Error::Input(format!(
            "fragment rasterizer backward: pix_to_face holds {bad}, not a face of {face_count}"
        ))),
    }
}

/// The settings of one fragment rasterization (PyTorch3D's `RasterizationSettings`, less
/// `bin_size` and `max_faces_per_bin`, which do not change the result).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FragmentSettings {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Squared NDC distance within which a pixel outside a face still sees it.
    pub blur_radius: f64,
    /// K: faces kept per pixel.
    pub faces_per_pixel: usize,
    /// Barycentrics corrected for perspective (`w_k z_{k+1} z_{k+2}`, normalized).
    pub perspective_correct: bool,
    /// Barycentrics clamped at 0 and renormalized (depth and outputs use them).
    pub clip_barycentric_coords: bool,
    /// Faces of negative screen area are skipped.
    pub cull_backfaces: bool,
}
