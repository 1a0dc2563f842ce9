//! Face setup on the GPU (`kernels/raster/raster/face_setup.comp`), one invocation per (view, face):
//! screen-space vertices from world positions, the inverse barycentric matrix with the SPEC's
//! determinant clamp, the front-facing flag and the grown screen box. The f64 twin is
//! [`reference::project_faces`] followed by [`reference::setup_face`].
//!
//! Lighting is not a GPU stage: like SoftRas, softvk lights colours in world space *before*
//! projection, on the host in f64 ([`crate::lighting`]), and uploads the lit per-face texels or
//! per-vertex colours as f32.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use crate::camera::{Camera, Projection, look_at};
use crate::error::{Error, Result};
use crate::gpu::{BufferRange, Context, Kernel, Recorder};
#[cfg(doc)]
use crate::raster::reference;
use crate::raster::settings::{Dist, RasterSettings};
use crate::raster::specs;

/// `Projection::Perspective` in [`GpuView::projection`] (`PROJ_PERSPECTIVE` in the kernel).
pub const PROJ_PERSPECTIVE: u32 = 0;
/// `Projection::Orthographic` in [`GpuView::projection`].
pub const PROJ_ORTHOGRAPHIC: u32 = 1;
/// `Projection::Matrix` in [`GpuView::projection`] (3×4 matrix with Brown distortion).
pub const PROJ_MATRIX: u32 = 2;

/// Bit of [`GpuFaceSetup::flags`]: front-facing in screen space (SPEC §1).
pub const FACE_FRONT: u32 = 1;
/// Bit of [`GpuFaceSetup::flags`]: every screen coordinate is finite (else the face is skipped).
pub const FACE_FINITE: u32 = 2;
/// Bit of [`GpuFaceSetup::flags`]: numerically degenerate at f32 rounding (infinite box).
pub const FACE_DEGENERATE: u32 = 4;

/// A face whose |det| is at most this multiple of f32 ε times the determinant's terms is treated
/// as degenerate (infinite box). The f64 twin uses 4 ε_f64; f32 uses a wide margin, since a face
/// not flagged must have a determinant accurate to a few percent for [`BARY_MARGIN`] to hold.
pub const DEGENERATE_ULPS: f32 = 256.0;

/// The barycentric box's growth `3√T/s` is multiplied by this: the f32 determinant of a face
/// not flagged degenerate is within ~5/[`DEGENERATE_ULPS`] (2 %) of the exact one, and the box
/// scales with it.
pub const BARY_MARGIN: f32 = 1.0 + 1.0 / 16.0;

/// Boxes are padded by this times the largest vertex coordinate magnitude (at least 1): the f32
/// rounding of barycentrics and distances near a box's edge is a few ulp of those magnitudes.
/// The twin's 1e-9 absolute pad is below f32 resolution.
pub const BBOX_PAD_REL: f32 = 1e-5;

/// One view as the setup kernel reads it. Twin of `View` in `face_setup.comp`; std430, 96 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuView {
    /// Perspective and orthographic: rows x, y, z of the look-at rotation (w unused).
    /// Matrix: the three rows of the 3×4 projection matrix P.
    pub rows: [[f32; 4]; 3],
    /// Eye position (w unused; unused for the matrix projection).
    pub eye: [f32; 4],
    /// Matrix: Brown distortion `k1, k2, p1, p2` (`k3` is [`GpuView::k3`]).
    pub dist: [f32; 4],
    /// [`PROJ_PERSPECTIVE`], [`PROJ_ORTHOGRAPHIC`] or [`PROJ_MATRIX`].
    pub projection: u32,
    /// Perspective: `tan(viewing angle)`; orthographic: the scale; matrix: `orig_size`.
    pub param: f32,
    /// Matrix: the distortion's `k3`.
    pub k3: f32,
    /// Which mesh of a batch this view shows (index into the batch's positions and colours).
    pub mesh: u32,
}

impl GpuView {
    /// The view of `camera` showing mesh 0, rounded to f32 from the twin's f64 look-at (or
    /// matrix).
    pub fn new(camera: &Camera) -> Result<GpuView> {
        let mut view = GpuView::default();
        let finite = |v: &[f64]| v.iter().all(|c| c.is_finite());
        let f4 = |r: [f64; 4]| r.map(|c| c as f32);
        match camera.projection {
            Projection::Perspective { viewing_angle_deg } => {
                view.projection = PROJ_PERSPECTIVE;
                view.param = viewing_angle_deg.to_radians().tan() as f32;
            }
            Projection::Orthographic { scale } => {
                view.projection = PROJ_ORTHOGRAPHIC;
                view.param = scale as f32;
            }
            Projection::Matrix {
                p,
                dist_coeffs,
                orig_size,
            } => {
                if !(finite(p.as_flattened()) && finite(&dist_coeffs) && orig_size.is_finite())
                    || orig_size <= 0.0
                {
                    return Err(Error::Input(format!(
                        "matrix projection is not finite or orig_size {orig_size} is not positive"
                    )));
                }
                view.projection = PROJ_MATRIX;
                view.rows = p.map(f4);
                let [k1, k2, p1, p2, k3] = dist_coeffs;
                view.dist = f4([k1, k2, p1, p2]);
                view.k3 = k3 as f32;
                view.param = orig_size as f32;
                return Ok(view);
            }
        }
        if !(view.param.is_finite() && camera.eye.is_finite()) {
            return Err(Error::Input(format!(
                "camera is not finite: eye {}, projection parameter {}",
                camera.eye, view.param
            )));
        }
        let r = look_at(camera.eye, camera.at, camera.up);
        if !r.iter().flatten().all(|c| c.is_finite()) {
            return Err(Error::Input(format!(
                "camera at {} looking at {} with up {} has no finite orientation",
                camera.eye, camera.at, camera.up
            )));
        }
        let row = |k: usize| [r[k][0] as f32, r[k][1] as f32, r[k][2] as f32, 0.0];
        view.rows = [row(0), row(1), row(2)];
        view.eye = [
            camera.eye.x as f32,
            camera.eye.y as f32,
            camera.eye.z as f32,
            0.0,
        ];
        Ok(view)
    }
}

/// One face in one view after setup. Twin of `FaceSetup` in `kernels/raster/include/raster.glsl` and of
/// [`reference::FaceSetup`]; std430, 128 bytes. The fourth words of `v` and `inv`, and `inv_det`,
/// are the reciprocals ([`crate::fmath::rcp`]) the fine and backward kernels multiply by, taken
/// once per face here rather than by every kernel that loads the face.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuFaceSetup {
    /// Screen-space vertices and their reciprocal depths `(x_s, y_s, z, 1 / z)`.
    pub v: [[f32; 4]; 3],
    /// Rows `(a, b, c, 1 / |e_k|²)` of `M_j` (determinant clamped to ±1e-10), where
    /// `w_k = a x + b y + c`; the fourth is the reciprocal squared length of edge k, from vertex
    /// k to the next (0 for a zero-length edge).
    pub inv: [[f32; 4]; 3],
    /// Grown screen box `[x_min, y_min, x_max, y_max]`.
    pub bbox: [f32; 4],
    /// [`FACE_FRONT`] | [`FACE_FINITE`] | [`FACE_DEGENERATE`].
    pub flags: u32,
    /// The mesh of the batch this face belongs to (its view's [`GpuView::mesh`]).
    pub mesh: u32,
    /// The screen determinant of `[[x], [y], [1, 1, 1]]`, unclamped: the one `inv` divides by
    /// and [`FACE_FRONT`] tests, which the fine and backward kernels read rather than recompute.
    /// For a look-at view it is taken from the world vertices (`look_at_det` in
    /// `face_setup.comp`), not from the f32 screen vertices, whose rounding can flip the sign of
    /// a face seen nearly edge-on.
    pub det: f32,
    /// 1 / the clamped determinant.
    pub inv_det: f32,
}

/// Push constants of `face_setup.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct SetupPush {
    face_count: u32,
    view_count: u32,
    dist: u32,
    radius: f32,
    degenerate_k: f32,
    bary_margin: f32,
    pad_rel: f32,
    vertex_count: u32,
    position_offset: u32,
    position_stride: u32,
}

/// Where vertex positions sit in a buffer: vertex `v`'s x, y, z are the floats at
/// `offset + stride · v`, `+ 1`, `+ 2` (counted in 32-bit floats from the bound range's start).
/// The default is packed xyz triples; a host's interleaved vertex buffer (position, normal,
/// uv, …) binds with its own stride ([`crate::raster::gpu::GpuScene::bind_positions`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VertexLayout {
    /// Floats before vertex 0's x.
    pub offset: u32,
    /// Floats from one vertex's x to the next's (at least 3).
    pub stride: u32,
}

impl Default for VertexLayout {
    fn default() -> Self {
        Self {
            offset: 0,
            stride: 3,
        }
    }
}

impl VertexLayout {
    /// Bytes a range must hold for `vertices` vertices; [`Error::Input`] for a stride under 3.
    pub fn bytes(&self, vertices: u64) -> Result<u64> {
        if self.stride < 3 {
            return Err(Error::Input(format!(
                "a vertex stride of {} floats cannot hold x, y and z",
                self.stride
            )));
        }
        Ok(match vertices {
            0 => 0,
            n => 4 * (u64::from(self.offset) + u64::from(self.stride) * (n - 1) + 3),
        })
    }
}

/// `DIST_*` of `raster.glsl`.
pub(crate) fn dist_code(dist: Dist) -> u32 {
    match dist {
        Dist::Euclidean => 0,
        Dist::Barycentric => 1,
        Dist::Hard => 2,
    }
}

/// Push constants of `vertex_project.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ProjectPush {
    vertex_count: u32,
    view_count: u32,
    position_offset: u32,
    position_stride: u32,
}

/// The face setup pipelines, made once per context: the projection of every vertex, then the
/// setup of every face from its projected corners.
pub struct FaceSetupKernel {
    project: Arc<Kernel>,
    kernel: Arc<Kernel>,
}

impl FaceSetupKernel {
    /// Builds the pipelines.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            project: ctx.kernel(&specs::VERTEX_PROJECT, &[])?,
            kernel: ctx.kernel(&specs::FACE_SETUP, &[])?,
        })
    }

    /// Bytes of the screen-vertex buffer [`FaceSetupKernel::record`] needs: 16 per vertex and
    /// view.
    pub fn screen_bytes(vertex_count: u32, view_count: u32) -> u64 {
        16 * u64::from(vertex_count) * u64::from(view_count)
    }

    /// Records the setup of `face_count` faces in `view_count` views into `setups`
    /// (`view_count * face_count` [`GpuFaceSetup`]s, view-major): first every vertex of every
    /// view on screen into `screen` (scratch of [`FaceSetupKernel::screen_bytes`], `(x_s, y_s,
    /// z, 0)` per vertex, view-major), then every face from its corners there.
    ///
    /// `positions` holds the world positions as packed `f32` triples (`vertex_count` per mesh of
    /// the batch, mesh after mesh), `faces` the vertex indices as packed `u32` triples, `views`
    /// one [`GpuView`] per view. `settings`' distance function and cut-off (σ, ε_d) choose the
    /// box growth as [`reference::face_screen_bbox_grown`] does.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        (positions, layout): (BufferRange<'_>, VertexLayout),
        faces: BufferRange<'_>,
        views: BufferRange<'_>,
        screen: BufferRange<'_>,
        setups: BufferRange<'_>,
        vertex_count: u32,
        face_count: u32,
        view_count: u32,
        settings: &RasterSettings,
    ) -> Result<()> {
        let dist = settings.dist;
        let n = u64::from(face_count) * u64::from(view_count);
        let need = n * std::mem::size_of::<GpuFaceSetup>() as u64;
        if setups.size < need || n > u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "face setup of {face_count} faces x {view_count} views needs {need} bytes; \
                 buffer `{}` has {}",
                setups.buffer.name(),
                setups.size
            )));
        }
        let vertices = u64::from(vertex_count) * u64::from(view_count);
        let screen_need = Self::screen_bytes(vertex_count, view_count);
        if screen.size < screen_need || vertices > u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "face setup of {vertex_count} vertices x {view_count} views needs {screen_need} \
                 bytes of screen vertices; buffer `{}` has {}",
                screen.buffer.name(),
                screen.size
            )));
        }
        let groups = vertices.div_ceil(u64::from(specs::VERTEX_PROJECT.workgroup_size[0]));
        rec.dispatch(
            &self.project,
            &specs::VertexProjectBindings {
                positions,
                views,
                screen,
            }
            .for_kernel(&self.project)?,
            &ProjectPush {
                vertex_count,
                view_count,
                position_offset: layout.offset,
                position_stride: layout.stride,
            },
            groups as u32,
        )?;
        rec.barrier();
        let push = SetupPush {
            face_count,
            view_count,
            dist: dist_code(dist),
            radius: if dist == Dist::Hard {
                0.0
            } else {
                settings.cutoff().sqrt() as f32
            },
            degenerate_k: DEGENERATE_ULPS * f32::EPSILON,
            bary_margin: BARY_MARGIN,
            pad_rel: BBOX_PAD_REL,
            vertex_count,
            position_offset: layout.offset,
            position_stride: layout.stride,
        };
        let groups = n.div_ceil(u64::from(specs::FACE_SETUP.workgroup_size[0]));
        rec.dispatch(
            &self.kernel,
            &specs::FaceSetupBindings {
                positions,
                faces,
                views,
                setups,
                screen,
            }
            .for_kernel(&self.kernel)?,
            &push,
            groups as u32,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_structs_match_the_kernels_layout() {
        assert_eq!(
            std::mem::size_of::<SetupPush>() as u32,
            specs::FACE_SETUP.push_constant_size
        );
        assert_eq!(std::mem::size_of::<GpuView>(), 96);
        assert_eq!(std::mem::offset_of!(GpuView, eye), 48);
        assert_eq!(std::mem::offset_of!(GpuView, projection), 80);
        assert_eq!(std::mem::offset_of!(GpuView, mesh), 92);
        assert_eq!(std::mem::size_of::<GpuFaceSetup>(), 128);
        assert_eq!(std::mem::offset_of!(GpuFaceSetup, inv), 48);
        assert_eq!(std::mem::offset_of!(GpuFaceSetup, bbox), 96);
        assert_eq!(std::mem::offset_of!(GpuFaceSetup, flags), 112);
        assert_eq!(std::mem::offset_of!(GpuFaceSetup, det), 120);
        assert_eq!(
            std::mem::size_of::<ProjectPush>() as u32,
            specs::VERTEX_PROJECT.push_constant_size
        );
        assert_eq!(specs::FACE_SETUP.bindings.len(), 5);
        assert_eq!(specs::VERTEX_PROJECT.workgroup_size, [64, 1, 1]);
        assert_eq!(specs::FACE_SETUP.workgroup_size, [64, 1, 1]);
    }

    #[test]
    fn non_finite_matrix_projection_is_an_input_error() {
        let cam = Camera {
            projection: Projection::Matrix {
                p: [
                    [1.0, 0.0, 0.0, 0.0],
                    [0.0, f64::NAN, 0.0, 0.0],
                    [0.0, 0.0, 1.0, 0.0],
                ],
                dist_coeffs: [0.0; 5],
                orig_size: 2.0,
            },
            ..Camera::default()
        };
        assert!(matches!(GpuView::new(&cam), Err(Error::Input(_))));
    }
}
