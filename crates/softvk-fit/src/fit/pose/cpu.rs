//! The f64 twin of [`PoseProblem::evaluate`](super::PoseProblem::evaluate).

use glam::DVec3;

use super::{Pose, pose_gradient};
use crate::camera::Camera;
use crate::error::Result;
use crate::fit::silhouette;
use crate::lighting::Lighting;
use crate::raster::reference::{MeshF64, render_f64};
use crate::raster::reference_grad::grad_f64;
use crate::raster::settings::RasterSettings;

/// `mesh` (at rest) moved to `pose` about `centre`.
pub fn posed(mesh: &MeshF64, centre: DVec3, pose: &Pose) -> MeshF64 {
    MeshF64 {
        positions: pose.apply(&mesh.positions, centre),
        ..mesh.clone()
    }
}

/// The image MSE of the f64 render at `pose` against `target` (RGBA per pixel).
pub fn loss(
    mesh: &MeshF64,
    centre: DVec3,
    camera: &Camera,
    lighting: &Lighting,
    settings: &RasterSettings,
    target: &[[f64; 4]],
    pose: &Pose,
) -> Result<f64> {
    let image = render_f64(&posed(mesh, centre, pose), camera, lighting, settings)?;
    Ok(silhouette::cpu::mse(&image, target).0)
}

/// The MSE and dL/d(ω, t): f64 render, MSE, f64 backward to the posed positions, and the
/// chain [`pose_gradient`].
pub fn loss_and_gradient(
    mesh: &MeshF64,
    centre: DVec3,
    camera: &Camera,
    lighting: &Lighting,
    settings: &RasterSettings,
    target: &[[f64; 4]],
    pose: &Pose,
) -> Result<(f64, [f64; 6])> {
    let moved = posed(mesh, centre, pose);
    let image = render_f64(&moved, camera, lighting, settings)?;
    let (loss, d_image) = silhouette::cpu::mse(&image, target);
    let g = grad_f64(
        &moved,
        std::slice::from_ref(camera),
        lighting,
        settings,
        &d_image,
    )?;
    Ok((
        loss,
        pose_gradient(&mesh.positions, centre, pose, &g.positions),
    ))
}
