//! `softvk._native`: the engine as Python sees it. The Python package (`softvk.torch`,
//! `softvk.soft_renderer`) wraps these calls in autograd functions and SoftRas's classes; this
//! module only moves arrays in and out of the engine.
//!
//! - One engine (a [`Context`] and a [`Renderer`]) per process, made on first use from the
//!   environment (`SOFTVK_DEVICE`, `SOFTVK_VALIDATION`, ...), and used by one call at a time:
//!   calls from several threads queue on its lock, with the GIL released while the device works.
//! - A forked child never touches its parent's engine (a Vulkan device does not survive a fork):
//!   it gets a clear error instead, and drops what it inherited without freeing it.
//! - [`rasterize`] is SoftRas's `soft_rasterize`: faces already in screen space, rendered with
//!   the identity camera ([`Camera::screen_space`]) and no lighting, so the engine's backward to
//!   world positions is the gradient with respect to the screen-space face vertices.
//! - [`render_mesh`] keeps the camera, the lighting and the face set-up on the device: vertices,
//!   faces and cameras in, images out.
//! - [`fragments`] is PyTorch3D's rasterizer (`softvk.pytorch3d`): the fragment kernels and
//!   their f64 twin, on packed projected faces.
//! - `nv_*` ([`nvdiffrast`]) are nvdiffrast's primitives (`softvk.nvdiffrast.torch`): hard
//!   rasterization with depth peeling, `interpolate` and `antialias`, forward and backward.
//! - [`reference_rasterize`] and [`reference_rasterize_grad`] are the f64 CPU twin of
//!   [`rasterize`] and its backward: the oracle of the tests, and what `soft_rasterize` computes
//!   for float64 tensors.
//! - A training loop renders the same shapes through the same views every iteration: when a
//!   render's [`Raster`] is dropped (its backward done), its scene is kept as a spare, and the
//!   next render of the same key (topology, views, lights, settings) writes its new vertices
//!   and textures into it ([`GpuScene::update_meshes`]) instead of making every buffer again;
//!   the buffers of its backward are kept with it ([`GradBuffers::fits`]), since on a CPU device
//!   new device memory costs a page fault per page at its first write.
//!
//! [`Context`]: softvk::gpu::Context
//! [`Renderer`]: softvk::raster::gpu::Renderer

use std::mem::ManuallyDrop;
use std::sync::Mutex;

use glam::DVec3;
use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArray1, PyReadonlyArrayDyn};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use softvk::camera::{Camera, Projection};
use softvk::lighting::{Directional, Lighting};
use softvk::mesh::Mesh;
use softvk::raster::backward::GradBuffers;
use softvk::raster::gpu::{GpuScene, Method};
use softvk::raster::settings::{Alpha, ColorMode, Dist, RasterSettings, Rgb};
use softvk::raster::{reference, reference_grad};

/// Lights from Python: `(ambient intensity, ambient colour, [(intensity, colour, direction)])`.
type PyLighting = (f64, [f64; 3], Vec<(f64, [f64; 3], [f64; 3])>);

mod convert;
mod engine;
mod error;
mod fragments;
mod io;
mod nvdiffrast;
mod nvtexture;

use convert::{array_of, checked, images_array, texture_res, triples};
use engine::{Engine, engine_fragments, forked, forked_error, with_engine};
use error::{to_py, value_error};

/// Scenes of dropped renders, newest last, for the next render of the same [`SceneKey`].
static SPARES: Mutex<Vec<Spare>> = Mutex::new(Vec::new());
/// How many spare scenes are kept (a loop alternates between at most two of a kind: the one
/// being differentiated and the next iteration's).
const MAX_SPARES: usize = 4;

/// The settings of one render: SoftRas's rasterizer arguments, the image size and how faces
/// meet pixels.
#[pyclass(frozen, module = "softvk._native")]
#[derive(Clone)]
struct Settings {
    raster: RasterSettings,
    method: Method,
    silhouettes: bool,
}

/// A dropped render's scene and its backward's buffers, kept for the next render of its key.
struct Spare {
    key: SceneKey,
    scene: GpuScene,
    grads: Option<GradBuffers>,
}

/// What a scene is made for: renders with equal keys can share one ([`SPARES`]).
#[derive(Clone, PartialEq)]
struct SceneKey {
    raster: RasterSettings,
    method: Method,
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
    fn new(
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
fn scene_for(
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

fn parse_choice<T: Copy>(what: &str, value: &str, choices: &[(&str, T)]) -> PyResult<T> {
    choices
        .iter()
        .find(|(name, _)| *name == value)
        .map(|(_, v)| *v)
        .ok_or_else(|| {
            let names: Vec<&str> = choices.iter().map(|c| c.0).collect();
            value_error(format!("{what} must be one of {names:?}, got {value:?}"))
        })
}

#[pymethods]
impl Settings {
    /// `Settings(width, height, *, sigma=1e-5, gamma=1e-4, near=1, far=100, eps=1e-3,
    /// dist_eps=1e-4, dist_func='euclidean', aggr_func_rgb='softmax', aggr_func_alpha='prod',
    /// background_color=(0, 0, 0), fill_back=True, texture_type='surface', tile=8,
    /// brute=False, silhouettes=False)`: SoftRas's names and defaults. `tile` is the tiled
    /// rasterizer's tile edge (a multiple of 8); `brute=True` runs SoftRas's
    /// every-face-for-every-pixel loop instead; `silhouettes=True` renders alpha alone (the
    /// same bits as a full render's alpha; RGB is left zero), skipping the depth and colour
    /// work forward and backward.
    #[new]
    #[pyo3(signature = (
        width, height, *, sigma = 1e-5, gamma = 1e-4, near = 1.0, far = 100.0, eps = 1e-3,
        dist_eps = 1e-4, dist_func = "euclidean", aggr_func_rgb = "softmax",
        aggr_func_alpha = "prod", background_color = (0.0, 0.0, 0.0), fill_back = true,
        texture_type = "surface", tile = softvk::raster::gpu::DEFAULT_TILE, brute = false,
        silhouettes = false,
    ))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        width: u32,
        height: u32,
        sigma: f64,
        gamma: f64,
        near: f64,
        far: f64,
        eps: f64,
        dist_eps: f64,
        dist_func: &str,
        aggr_func_rgb: &str,
        aggr_func_alpha: &str,
        background_color: (f64, f64, f64),
        fill_back: bool,
        texture_type: &str,
        tile: u32,
        brute: bool,
        silhouettes: bool,
    ) -> PyResult<Self> {
        let raster = RasterSettings {
            width,
            height,
            sigma,
            gamma,
            near,
            far,
            eps,
            dist_eps,
            dist: parse_choice(
                "dist_func",
                dist_func,
                &[
                    ("euclidean", Dist::Euclidean),
                    ("barycentric", Dist::Barycentric),
                    ("hard", Dist::Hard),
                ],
            )?,
            rgb: parse_choice(
                "aggr_func_rgb",
                aggr_func_rgb,
                &[("softmax", Rgb::Softmax), ("hard", Rgb::Hard)],
            )?,
            alpha: parse_choice(
                "aggr_func_alpha",
                aggr_func_alpha,
                &[
                    ("prod", Alpha::Prod),
                    ("sum", Alpha::Sum),
                    ("hard", Alpha::Hard),
                ],
            )?,
            background: [background_color.0, background_color.1, background_color.2],
            double_sided: fill_back,
            antialias: false,
            color_mode: parse_choice(
                "texture_type",
                texture_type,
                &[
                    ("surface", ColorMode::Surface),
                    ("vertex", ColorMode::Vertex),
                ],
            )?,
        };
        raster.validate().map_err(|e| to_py(e.into()))?;
        let method = if brute {
            Method::Brute
        } else {
            softvk::raster::gpu::Method::check_tile(tile).map_err(to_py)?;
            Method::Tiled { tile }
        };
        Ok(Settings {
            raster,
            method,
            silhouettes,
        })
    }

    /// `(height, width)` of the images.
    #[getter]
    fn shape(&self) -> (u32, u32) {
        (self.raster.height, self.raster.width)
    }
}

/// SoftRas's `face_vertices` `[B, F, 3, 3]` and `textures` (`[B, F, R², 3]` surface, `[B, F, 3,
/// 3]` vertex), checked: one mesh a batch element, three vertices a face (face `j` = vertices
/// `3j, 3j + 1, 3j + 2`).
struct FaceInputs<'a, T> {
    vertices: &'a [T],
    textures: &'a [T],
    batch: usize,
    faces: usize,
    /// Colours a face: R² texels, or 3 corners.
    per_face: usize,
    texture_res: u32,
    mode: ColorMode,
}

impl<'a, T: numpy::Element + Copy> FaceInputs<'a, T> {
    fn new(
        face_vertices: &'a PyReadonlyArrayDyn<'_, T>,
        textures: &'a PyReadonlyArrayDyn<'_, T>,
        mode: ColorMode,
    ) -> PyResult<Self> {
        let (vertices, shape) = checked(
            "face_vertices",
            face_vertices,
            &[None, None, Some(3), Some(3)],
        )?;
        let (batch, faces) = (shape[0], shape[1]);
        let (textures, tshape) = checked(
            "textures",
            textures,
            &[Some(batch), Some(faces), None, Some(3)],
        )?;
        let per_face = tshape[2];
        let texture_res = match mode {
            ColorMode::Surface => texture_res(per_face)?,
            ColorMode::Vertex if per_face == 3 => 1,
            ColorMode::Vertex => {
                return Err(value_error(format!(
                    "vertex textures need 3 colours a face, got {per_face}"
                )));
            }
        };
        if batch == 0 || faces == 0 {
            return Err(value_error(format!(
                "nothing to render: {batch} meshes of {faces} faces"
            )));
        }
        Ok(FaceInputs {
            vertices,
            textures,
            batch,
            faces,
            per_face,
            texture_res,
            mode,
        })
    }

    fn face_list(&self) -> Vec<[u32; 3]> {
        (0..self.faces as u32)
            .map(|j| [3 * j, 3 * j + 1, 3 * j + 2])
            .collect()
    }

    /// Batch element `b`: its vertex positions, and its colours as (texels, vertex colours).
    #[allow(clippy::type_complexity)]
    fn mesh_parts(&self, b: usize, white: T) -> (Vec<[T; 3]>, Vec<[T; 3]>, Option<Vec<[T; 3]>>) {
        let (v, t) = (9 * self.faces, 3 * self.per_face * self.faces);
        let positions = triples(&self.vertices[b * v..(b + 1) * v]);
        let colors = triples(&self.textures[b * t..(b + 1) * t]);
        match self.mode {
            ColorMode::Surface => (positions, colors, None),
            ColorMode::Vertex => (positions, vec![[white; 3]; self.faces], Some(colors)),
        }
    }
}

impl FaceInputs<'_, f32> {
    fn meshes(&self) -> Vec<Mesh> {
        let faces = self.face_list();
        (0..self.batch)
            .map(|b| {
                let (positions, textures, vertex_colors) = self.mesh_parts(b, 1.0);
                Mesh {
                    positions,
                    faces: faces.clone(),
                    texture_res: self.texture_res,
                    textures,
                    vertex_colors,
                }
            })
            .collect()
    }
}

impl FaceInputs<'_, f64> {
    fn meshes_f64(&self) -> Vec<reference::MeshF64> {
        let faces = self.face_list();
        (0..self.batch)
            .map(|b| {
                let (positions, textures, vertex_colors) = self.mesh_parts(b, 1.0);
                reference::MeshF64 {
                    positions: positions.into_iter().map(DVec3::from).collect(),
                    faces: faces.clone(),
                    texture_res: self.texture_res,
                    textures,
                    vertex_colors,
                }
            })
            .collect()
    }
}

/// What the backward needs: the rendered scene, kept on the device, and how its arrays map
/// back to the caller's.
#[pyclass(module = "softvk._native")]
struct Raster {
    /// `None` once [`Raster::release`]d. Never dropped in a forked child (see [`Drop`]).
    scene: Option<ManuallyDrop<GpuScene>>,
    /// What the scene was made for: it goes back to [`SPARES`] under this key when dropped.
    key: SceneKey,
    /// The buffers of the scene's last backward, kept for the next (a spare's come with it).
    grads: Mutex<Option<GradBuffers>>,
    kind: RasterKind,
}

#[derive(Clone, Copy)]
enum RasterKind {
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
fn render<'py>(
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

/// Frees the scenes kept for reuse (they hold device memory until the next render of their
/// kind, or until this is called).
#[pyfunction]
fn release_cached_scenes() {
    if forked().is_none() {
        SPARES.lock().unwrap_or_else(|e| e.into_inner()).clear();
        fragments::release_pool();
    }
}

/// `rasterize(face_vertices, textures, settings) -> (images, raster)`: SoftRas's
/// `soft_rasterize`. `face_vertices` `[B, F, 3, 3]` float32 in screen space (x, y, depth);
/// `textures` `[B, F, R², 3]` (surface) or `[B, F, 3, 3]` (vertex), float32, not lit. Returns
/// the RGBA images `[B, H, W, 4]` (row 0 at the top) and the [`Raster`] that differentiates
/// them.
#[pyfunction]
fn rasterize<'py>(
    py: Python<'py>,
    face_vertices: PyReadonlyArrayDyn<'py, f32>,
    textures: PyReadonlyArrayDyn<'py, f32>,
    settings: &Settings,
) -> PyResult<(Bound<'py, PyAny>, Raster)> {
    let inputs = FaceInputs::new(&face_vertices, &textures, settings.raster.color_mode)?;
    let (batch, faces, per_face) = (inputs.batch, inputs.faces, inputs.per_face);
    let meshes = inputs.meshes();
    let views: Vec<(usize, Camera)> = (0..batch).map(|b| (b, Camera::screen_space())).collect();
    let kind = RasterKind::Faces {
        batch,
        faces,
        per_face,
    };
    render(py, settings, &meshes, &views, &Lighting::unlit(), kind)
}

/// `reference_rasterize(face_vertices, textures, settings)`: the f64 CPU twin of
/// [`rasterize`] (float64 arrays in and out): the oracle softvk's kernels are tested against.
#[pyfunction]
fn reference_rasterize<'py>(
    py: Python<'py>,
    face_vertices: PyReadonlyArrayDyn<'py, f64>,
    textures: PyReadonlyArrayDyn<'py, f64>,
    settings: &Settings,
) -> PyResult<Bound<'py, PyAny>> {
    let inputs = FaceInputs::new(&face_vertices, &textures, settings.raster.color_mode)?;
    let (batch, s) = (inputs.batch, settings.raster);
    let meshes = inputs.meshes_f64();
    let images = py.detach(|| -> PyResult<Vec<f64>> {
        let mut out = Vec::with_capacity(batch * (s.width * s.height) as usize * 4);
        for mesh in &meshes {
            let image =
                reference::render_f64(mesh, &Camera::screen_space(), &Lighting::unlit(), &s)
                    .map_err(|e| to_py(e.into()))?;
            out.extend(image.into_iter().flatten());
        }
        Ok(out)
    })?;
    images_array(py, images, (batch, s.height as usize, s.width as usize))
}

/// `reference_rasterize_grad(face_vertices, textures, settings, grad_images)`: the f64 CPU
/// twin's backward of [`reference_rasterize`] (float64 throughout): dL/d(face vertices)
/// `[B, F, 3, 3]` and dL/d(textures) (their shape) given dL/d(images) `[B, H, W, 4]`. With
/// [`reference_rasterize`] it is what `soft_rasterize` computes for float64 tensors, as SoftRas's
/// kernels compute doubles in double (`torch.autograd.gradcheck`).
#[pyfunction]
fn reference_rasterize_grad<'py>(
    py: Python<'py>,
    face_vertices: PyReadonlyArrayDyn<'py, f64>,
    textures: PyReadonlyArrayDyn<'py, f64>,
    settings: &Settings,
    grad_images: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Bound<'py, PyTuple>> {
    let inputs = FaceInputs::new(&face_vertices, &textures, settings.raster.color_mode)?;
    let (batch, faces, per_face, s) =
        (inputs.batch, inputs.faces, inputs.per_face, settings.raster);
    let (height, width) = (s.height as usize, s.width as usize);
    let (d_image, _) = checked(
        "grad_images",
        &grad_images,
        &[Some(batch), Some(height), Some(width), Some(4)],
    )?;
    let d_image: &[[f64; 4]] = bytemuck::cast_slice(d_image);
    let meshes = inputs.meshes_f64();
    let (positions, colors) = py.detach(|| -> PyResult<(Vec<f64>, Vec<f64>)> {
        let (mut positions, mut colors) = (Vec::new(), Vec::new());
        for (b, mesh) in meshes.iter().enumerate() {
            let upstream = &d_image[b * height * width..(b + 1) * height * width];
            let g = reference_grad::grad_f64(
                mesh,
                &[Camera::screen_space()],
                &Lighting::unlit(),
                &s,
                upstream,
            )
            .map_err(|e| to_py(e.into()))?;
            positions.extend(g.positions.into_iter().flatten());
            colors.extend(g.colors.into_iter().flatten());
        }
        Ok((positions, colors))
    })?;
    let d_pos = positions
        .into_pyarray(py)
        .reshape([batch, faces, 3, 3])?
        .into_any();
    let d_tex = colors
        .into_pyarray(py)
        .reshape([batch, faces, per_face, 3])?
        .into_any();
    PyTuple::new(py, [d_pos, d_tex])
}

/// A camera from Python: `('look_at', eye, at, up, viewing_angle_or_None, scale)` (perspective
/// with the viewing angle in degrees, or orthographic with `scale` when the angle is `None`),
/// or `('projection', P (12 floats, rows), dist_coeffs (5), orig_size)`.
fn camera_from(item: &Bound<'_, PyAny>) -> PyResult<Camera> {
    let kind: String = item.get_item(0)?.extract()?;
    let vec3 = |i: usize| -> PyResult<DVec3> {
        let v: [f64; 3] = item.get_item(i)?.extract()?;
        Ok(DVec3::from(v))
    };
    match kind.as_str() {
        "look_at" => {
            let angle: Option<f64> = item.get_item(4)?.extract()?;
            let scale: f64 = item.get_item(5)?.extract()?;
            Ok(Camera {
                eye: vec3(1)?,
                at: vec3(2)?,
                up: vec3(3)?,
                projection: match angle {
                    Some(viewing_angle_deg) => Projection::Perspective { viewing_angle_deg },
                    None => Projection::Orthographic { scale },
                },
            })
        }
        "projection" => {
            let p: [f64; 12] = item.get_item(1)?.extract()?;
            let dist_coeffs: [f64; 5] = item.get_item(2)?.extract()?;
            let orig_size: f64 = item.get_item(3)?.extract()?;
            Ok(Camera {
                projection: Projection::Matrix {
                    p: [
                        [p[0], p[1], p[2], p[3]],
                        [p[4], p[5], p[6], p[7]],
                        [p[8], p[9], p[10], p[11]],
                    ],
                    dist_coeffs,
                    orig_size,
                },
                ..Camera::default()
            })
        }
        other => Err(value_error(format!(
            "camera kind must be 'look_at' or 'projection', got {other:?}"
        ))),
    }
}

/// `render_mesh(vertices, faces, textures, view_mesh, cameras, lighting, settings)`:
/// `vertices` `[B, V, 3]` float32 (world), `faces` `[F, 3]` int64 shared by the batch,
/// `textures` `[B, F, R², 3]` (surface) or `[B, V, 3]` (vertex) float32 before lighting;
/// view `i` shows mesh `view_mesh[i]` through `cameras[i]` (see [`camera_from`]); `lighting`
/// is `(ambient_intensity, ambient_color, [(intensity, color, direction), ...])`. Lighting,
/// camera and face set-up run in the engine. Returns `(images [views, H, W, 4], raster)`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn render_mesh<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArrayDyn<'py, f32>,
    faces: PyReadonlyArrayDyn<'py, i64>,
    textures: PyReadonlyArrayDyn<'py, f32>,
    view_mesh: PyReadonlyArray1<'py, i64>,
    cameras: Vec<Bound<'py, PyAny>>,
    lighting: PyLighting,
    settings: &Settings,
) -> PyResult<(Bound<'py, PyAny>, Raster)> {
    let (verts, vshape) = checked("vertices", &vertices, &[None, None, Some(3)])?;
    let (batch, nv) = (vshape[0], vshape[1]);
    let (face_idx, fshape) = checked("faces", &faces, &[None, Some(3)])?;
    let nf = fshape[0];
    let mode = settings.raster.color_mode;
    let (tex, tshape) = match mode {
        ColorMode::Surface => checked(
            "textures",
            &textures,
            &[Some(batch), Some(nf), None, Some(3)],
        )?,
        ColorMode::Vertex => checked("textures", &textures, &[Some(batch), Some(nv), Some(3)])?,
    };
    let res = match mode {
        ColorMode::Surface => texture_res(tshape[2])?,
        ColorMode::Vertex => 1,
    };
    let view_mesh = view_mesh
        .as_slice()
        .map_err(|_| value_error("view_mesh is not contiguous".into()))?;
    if view_mesh.len() != cameras.len() {
        return Err(value_error(format!(
            "{} cameras for {} views",
            cameras.len(),
            view_mesh.len()
        )));
    }
    let mut views = Vec::with_capacity(cameras.len());
    for (&m, camera) in view_mesh.iter().zip(&cameras) {
        let m = usize::try_from(m)
            .ok()
            .filter(|&m| m < batch)
            .ok_or_else(|| value_error(format!("a view shows mesh {m} of a batch of {batch}")))?;
        views.push((m, camera_from(camera)?));
    }
    let mut face_list = Vec::with_capacity(nf);
    for f in face_idx.chunks_exact(3) {
        let mut idx = [0u32; 3];
        for (k, &i) in f.iter().enumerate() {
            idx[k] = u32::try_from(i)
                .ok()
                .filter(|&i| (i as usize) < nv)
                .ok_or_else(|| {
                    value_error(format!("face index {i} is outside the {nv} vertices"))
                })?;
        }
        face_list.push(idx);
    }
    let colors_per_mesh = tex.len() / 3 / batch.max(1);
    let meshes: Vec<Mesh> = (0..batch)
        .map(|b| {
            let colors = triples(&tex[b * 3 * colors_per_mesh..(b + 1) * 3 * colors_per_mesh]);
            let (textures, vertex_colors) = match mode {
                ColorMode::Surface => (colors, None),
                ColorMode::Vertex => (vec![[1.0; 3]; nf], Some(colors)),
            };
            Mesh {
                positions: triples(&verts[b * 3 * nv..(b + 1) * 3 * nv]),
                faces: face_list.clone(),
                texture_res: res,
                textures,
                vertex_colors,
            }
        })
        .collect();
    let (ambient, ambient_color, directionals) = lighting;
    let lighting = Lighting {
        ambient_intensity: ambient,
        ambient_color,
        directionals: directionals
            .into_iter()
            .map(|(intensity, color, direction)| Directional {
                intensity,
                color,
                direction,
            })
            .collect(),
    };
    let n_views = views.len();
    if meshes.is_empty() || nf == 0 || n_views == 0 {
        return Err(value_error(format!(
            "nothing to render: {batch} meshes of {nf} faces, {n_views} views"
        )));
    }
    let kind = RasterKind::Mesh {
        batch,
        vertices: nv,
        colors: colors_per_mesh,
        views: n_views,
    };
    render(py, settings, &meshes, &views, &lighting, kind)
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Settings>()?;
    m.add_class::<Raster>()?;
    m.add_function(wrap_pyfunction!(rasterize, m)?)?;
    m.add_function(wrap_pyfunction!(reference_rasterize, m)?)?;
    m.add_function(wrap_pyfunction!(reference_rasterize_grad, m)?)?;
    m.add_function(wrap_pyfunction!(render_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(engine::device_name, m)?)?;
    m.add_function(wrap_pyfunction!(release_cached_scenes, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_exr, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_exr, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_rgb, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_png, m)?)?;
    m.add_function(wrap_pyfunction!(engine::is_forked_child, m)?)?;
    fragments::register(m)?;
    nvdiffrast::register(m)?;
    nvtexture::register(m)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
