//! The scene cache. A training loop renders the same shapes through the same views every
//! iteration: a dropped render's scene and its backward's buffers are kept as a [`Spare`]
//! ([`SPARES`]), and the next render of the same [`SceneKey`] (topology, views, lights,
//! settings) writes its meshes into it ([`scene_for`]) instead of making every buffer again.
//! `release_cached_scenes` frees them.

use std::sync::Mutex;

use pyo3::prelude::*;
use softvk::camera::Camera;
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::backward::GradBuffers;
use softvk::raster::gpu::{GpuScene, Method};
use softvk::raster::settings::RasterSettings;

use crate::engine::{Engine, forked};
use crate::fragments;
use crate::soft::settings::Settings;

/// Scenes of dropped renders, newest last, for the next render of the same [`SceneKey`].
pub(crate) static SPARES: Mutex<Vec<Spare>> = Mutex::new(Vec::new());
/// How many spare scenes are kept (a loop alternates between at most two of a kind: the one
/// being differentiated and the next iteration's).
pub(crate) const MAX_SPARES: usize = 4;

/// A dropped render's scene and its backward's buffers, kept for the next render of its key.
pub(crate) struct Spare {
    pub(crate) key: SceneKey,
    pub(crate) scene: GpuScene,
    pub(crate) grads: Option<GradBuffers>,
}

/// What a scene is made for: renders with equal keys can share one ([`SPARES`]).
#[derive(Clone, PartialEq)]
pub(crate) struct SceneKey {
    raster: RasterSettings,
    pub(crate) method: Method,
    silhouettes: bool,
    faces: Vec<[u32; 3]>,
    meshes: usize,
    vertices: usize,
    texture_res: u32,
    vertex_colors: bool,
    views: Vec<(usize, Camera)>,
    lighting: Lighting,
}

impl SceneKey {
    pub(crate) fn new(
        settings: &Settings,
        meshes: &[Mesh],
        views: &[(usize, Camera)],
        lighting: &Lighting,
    ) -> Self {
        let first = &meshes[0];
        SceneKey {
            raster: settings.raster,
            method: settings.method,
            silhouettes: settings.silhouettes,
            faces: first.faces.clone(),
            meshes: meshes.len(),
            vertices: first.positions.len(),
            texture_res: first.texture_res,
            vertex_colors: first.vertex_colors.is_some(),
            views: views.to_vec(),
            lighting: lighting.clone(),
        }
    }
}

/// A scene for `meshes` as `key` says: a spare of that key with the meshes written into it
/// (and its backward's buffers), or a new one.
pub(crate) fn scene_for(
    engine: &Engine,
    key: &SceneKey,
    meshes: &[Mesh],
) -> softvk::Result<(GpuScene, Option<GradBuffers>)> {
    let spare = {
        let mut spares = SPARES.lock().unwrap_or_else(|e| e.into_inner());
        spares
            .iter()
            .rposition(|spare| spare.key == *key)
            .map(|i| spares.remove(i))
    };
    if let Some(mut spare) = spare {
        spare.scene.update_meshes(&engine.ctx, meshes)?;
        return Ok((spare.scene, spare.grads));
    }
    let mut scene = engine.renderer.prepare_batch(
        &engine.ctx,
        meshes,
        &key.views,
        &key.lighting,
        &key.raster,
    )?;
    scene.set_silhouette_only(key.silhouettes);
    Ok((scene, None))
}

/// Frees the scenes kept for reuse (they hold device memory until the next render of their
/// kind, or until this is called).
#[pyfunction]
pub(crate) fn release_cached_scenes() {
    if forked().is_none() {
        SPARES.lock().unwrap_or_else(|e| e.into_inner()).clear();
        fragments::release_pool();
    }
}
