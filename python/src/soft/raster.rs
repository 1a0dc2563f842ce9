//! `Raster`: what a render's backward needs, its scene kept on the device, and [`render`], the
//! forward that `rasterize` and `render_mesh` share. A dropped `Raster`'s scene goes back to
//! the scene cache ([`crate::scene`]) for the next render of its key.

use std::mem::ManuallyDrop;
use std::sync::Mutex;

use numpy::PyReadonlyArrayDyn;
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use softvk::camera::Camera;
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::backward::GradBuffers;
use softvk::raster::gpu::GpuScene;

use crate::convert::{array_of, checked, images_array};
use crate::engine::{forked, forked_error, with_engine};
use crate::scene::{MAX_SPARES, SPARES, SceneKey, Spare, scene_for};
use crate::soft::settings::Settings;

/// What the backward needs: the rendered scene, kept on the device, and how its arrays map
/// back to the caller's.
#[pyclass(module = "softvk._native")]
pub(crate) struct Raster {
    /// `None` once [`Raster::release`]d. Never dropped in a forked child (see [`Drop`]).
    scene: Option<ManuallyDrop<GpuScene>>,
    /// What the scene was made for: it goes back to [`SPARES`] under this key when dropped.
    key: SceneKey,
    /// The buffers of the scene's last backward, kept for the next (a spare's come with it).
    grads: Mutex<Option<GradBuffers>>,
    kind: RasterKind,
}

#[derive(Clone, Copy)]
pub(crate) enum RasterKind {
    /// `rasterize`: gradients go to `[B, F, 3, 3]` face vertices and `[B, F, T, 3]` textures.
    Faces {
        batch: usize,
        faces: usize,
        per_face: usize,
    },
    /// `render_mesh`: to `[B, V, 3]` vertices and `[B, T..., 3]` textures, and to the eyes.
    Mesh {
        batch: usize,
        vertices: usize,
        colors: usize,
        views: usize,
    },
}

impl Raster {
    /// The render's scene and backward buffers, taken out of it; `None` in a forked child,
    /// which must not free its parent's device memory and leaks them instead (the scene is a
    /// `ManuallyDrop`).
    fn take_buffers(&mut self) -> Option<(Option<GpuScene>, Option<GradBuffers>)> {
        let scene = self.scene.take();
        let grads = self
            .grads
            .get_mut()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        if forked().is_some() {
            std::mem::forget(grads);
            return None;
        }
        Some((scene.map(ManuallyDrop::into_inner), grads))
    }
}

impl Drop for Raster {
    fn drop(&mut self) {
        if let Some((Some(scene), grads)) = self.take_buffers() {
            // Kept for the next render of its kind; the oldest spare goes (its buffers free
            // themselves through the context, which outlives them).
            let spare = Spare {
                key: self.key.clone(),
                scene,
                grads,
            };
            let mut spares = SPARES.lock().unwrap_or_else(|e| e.into_inner());
            spares.push(spare);
            if spares.len() > MAX_SPARES {
                spares.remove(0);
            }
        }
    }
}

#[pymethods]
impl Raster {
    /// `backward(grad_images, alpha_only=False, eyes=False)`: dL/d(inputs) given dL/d(images)
    /// `[views, H, W, 4]` (float32). `alpha_only` declares the RGB part of the upstream
    /// gradient zero (a silhouette loss): the colour terms are skipped, which changes no bit.
    /// Returns `(d_positions, d_textures, d_eyes)`: for `rasterize`, `[B, F, 3, 3]` and
    /// `[B, F, T, 3]`; for `render_mesh`, `[B, V, 3]` and the textures' shape, and with `eyes`,
    /// `[views, 3]` (else `None`).
    #[pyo3(signature = (grad_images, alpha_only = false, eyes = false))]
    fn backward<'py>(
        &self,
        py: Python<'py>,
        grad_images: PyReadonlyArrayDyn<'py, f32>,
        alpha_only: bool,
        eyes: bool,
    ) -> PyResult<Bound<'py, PyTuple>> {
        if let Some(owner) = forked() {
            return Err(forked_error(owner));
        }
        let scene: &GpuScene = self.scene.as_deref().ok_or_else(|| {
            PyRuntimeError::new_err("softvk: this render was released; its backward is gone")
        })?;
        let s = scene.settings();
        let views = scene.view_count() as usize;
        let (d_image, _) = checked(
            "grad_images",
            &grad_images,
            &[
                Some(views),
                Some(s.height as usize),
                Some(s.width as usize),
                Some(4),
            ],
        )?;
        let d_image: &[[f32; 4]] = bytemuck::cast_slice(d_image);
        let method = self.key.method;
        let eyes = eyes && matches!(self.kind, RasterKind::Mesh { .. });
        let grads = with_engine(py, |engine| {
            // The scene is kept for this backward alone: nothing changes it after its run.
            let binned = scene
                .last_run()
                .filter(|run| run.binned().method() == method)
                .ok_or_else(|| {
                    softvk::Error::Input("this render's forward is gone; render again".into())
                })?
                .binned();
            let mut kept = self.grads.lock().unwrap_or_else(|e| e.into_inner());
            let gb = match kept.take() {
                Some(gb) if gb.fits(&binned) => kept.insert(gb),
                _ => kept.insert(GradBuffers::new(&engine.ctx, &binned)?),
            };
            gb.set_alpha_only(alpha_only);
            gb.set_d_image(&engine.ctx, scene, d_image)?;
            let kernels = engine.renderer.grad_kernels();
            engine
                .ctx
                .submit_and_wait(|rec| kernels.record(rec, &binned, gb, &gb.io()))?;
            kernels.finish(&engine.ctx, scene, gb, &gb.io(), eyes)
        })?;
        let narrow =
            |v: &[[f64; 3]]| -> Vec<f32> { v.iter().flat_map(|g| g.map(|c| c as f32)).collect() };
        let (d_pos, d_tex, d_eyes) = match self.kind {
            RasterKind::Faces {
                batch,
                faces,
                per_face,
            } => (
                array_of(py, narrow(&grads.positions), &[batch, faces, 3, 3])?,
                array_of(py, narrow(&grads.colors), &[batch, faces, per_face, 3])?,
                py.None().into_bound(py),
            ),
            RasterKind::Mesh {
                batch,
                vertices,
                colors,
                views,
            } => {
                let d_eyes = if eyes {
                    let e: Vec<f32> = grads
                        .cameras
                        .iter()
                        .flat_map(|c| c.eye.map(|x| x as f32))
                        .collect();
                    array_of(py, e, &[views, 3])?
                } else {
                    py.None().into_bound(py)
                };
                (
                    array_of(py, narrow(&grads.positions), &[batch, vertices, 3])?,
                    array_of(py, narrow(&grads.colors), &[batch, colors, 3])?,
                    d_eyes,
                )
            }
        };
        PyTuple::new(py, [d_pos, d_tex, d_eyes])
    }

    /// Frees the render's device buffers now (its backward is gone); the garbage collector
    /// would otherwise free them with this object.
    fn release(&mut self) {
        drop(self.take_buffers());
    }
}

/// Renders `meshes` through `views` (in a spare scene of their key if there is one) and reads
/// the images back: `[views, H, W, 4]`, and the [`Raster`] that differentiates them.
pub(crate) fn render<'py>(
    py: Python<'py>,
    settings: &Settings,
    meshes: &[Mesh],
    views: &[(usize, Camera)],
    lighting: &Lighting,
    kind: RasterKind,
) -> PyResult<(Bound<'py, PyAny>, Raster)> {
    let key = SceneKey::new(settings, meshes, views, lighting);
    let (scene, grads, images) = with_engine(py, |engine| {
        let (mut scene, grads) = scene_for(engine, &key, meshes)?;
        engine.renderer.run(&engine.ctx, &mut scene, key.method)?;
        let s = scene.settings();
        let pixels = (s.width * s.height * scene.view_count()) as usize;
        let images: Vec<[f32; 4]> = engine.ctx.read_buffer(scene.output(), 0, pixels)?;
        Ok((scene, grads, images.into_flattened()))
    })?;
    let s = settings.raster;
    let dims = (views.len(), s.height as usize, s.width as usize);
    Ok((
        images_array(py, images, dims)?,
        Raster {
            scene: Some(ManuallyDrop::new(scene)),
            key,
            grads: Mutex::new(grads),
            kind,
        },
    ))
}
