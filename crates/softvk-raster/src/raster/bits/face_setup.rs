//! The bit twin of the projection and face set-up: `vertex_project.comp` (`view.glsl`'s
//! `to_screen`) and `face_setup.comp` (with `raster.glsl`'s `face_reciprocals`) in f32,
//! operation for operation, from the world positions, the faces and the views the device reads.
//! Every float operation of those kernels is decorated `NoContraction` (build.rs), so each is
//! one IEEE operation here too; divisions are [`crate::fmath`]'s.

use super::{MIN_DET, V3, reciprocals};
use crate::fmath;
use crate::raster::settings::{Dist, RasterSettings};
use crate::raster::setup::{
    BARY_MARGIN, BBOX_PAD_REL, DEGENERATE_ULPS, FACE_DEGENERATE, FACE_FINITE, FACE_FRONT,
    GpuFaceSetup, GpuView, PROJ_MATRIX, PROJ_ORTHOGRAPHIC, PROJ_PERSPECTIVE,
};

fn sub3(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `project_matrix` of `view.glsl`.
fn project_matrix(view: &GpuView, p: V3) -> V3 {
    let row = |k: usize| {
        let r = view.rows[k];
        ((r[0] * p[0] + r[1] * p[1]) + r[2] * p[2]) + r[3]
    };
    let (x, y, z) = (row(0), row(1), row(2));
    let x1 = fmath::div_rn(x, z + 1e-5);
    let y1 = fmath::div_rn(y, z + 1e-5);
    let [k1, k2, p1, p2] = view.dist;
    let r2 = x1 * x1 + y1 * y1;
    let radial = ((1.0 + k1 * r2) + k2 * r2 * r2) + view.k3 * r2 * r2 * r2;
    let x2 = (x1 * radial + 2.0 * p1 * x1 * y1) + p2 * (r2 + 2.0 * x1 * x1);
    let y2 = (y1 * radial + p1 * (r2 + 2.0 * y1 * y1)) + 2.0 * p2 * x1 * y1;
    let half_size = view.param * 0.5;
    [
        fmath::div_rn(x2 - half_size, half_size),
        fmath::div_rn(y2 - half_size, half_size),
        z,
    ]
}

/// `to_screen` of `view.glsl` (`Camera::to_screen` in f32): the screen vertex
/// `vertex_project.comp` writes for world position `p`.
pub fn to_screen(view: &GpuView, p: V3) -> V3 {
    if view.projection == PROJ_MATRIX {
        return project_matrix(view, p);
    }
    let d = sub3(p, [view.eye[0], view.eye[1], view.eye[2]]);
    let row = |k: usize| {
        let r = view.rows[k];
        (r[0] * d[0] + r[1] * d[1]) + r[2] * d[2]
    };
    let c = [row(0), row(1), row(2)];
    if view.projection == PROJ_PERSPECTIVE {
        return [
            fmath::div_rn(fmath::div_rn(c[0], c[2]), view.param),
            fmath::div_rn(fmath::div_rn(c[1], c[2]), view.param),
            c[2],
        ];
    }
    [c[0] * view.param, c[1] * view.param, c[2]]
}

/// `look_at_det` of `face_setup.comp`: the screen determinant of a look-at view's face from its
/// world vertices and screen depths.
fn look_at_det(view: &GpuView, q: [V3; 3], z: V3) -> f32 {
    let a = sub3(q[1], q[0]);
    let b = sub3(q[2], q[0]);
    let n = [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ];
    let (rx, ry, rz) = (view.rows[0], view.rows[1], view.rows[2]);
    let k = [
        rx[1] * ry[2] - rx[2] * ry[1],
        rx[2] * ry[0] - rx[0] * ry[2],
        rx[0] * ry[1] - rx[1] * ry[0],
    ];
    if view.projection == PROJ_ORTHOGRAPHIC {
        let kn = (k[0] * n[0] + k[1] * n[1]) + k[2] * n[2];
        let s2 = view.param * view.param;
        return s2 * kn;
    }
    let e = sub3(q[0], [view.eye[0], view.eye[1], view.eye[2]]);
    let triple = (n[0] * e[0] + n[1] * e[1]) + n[2] * e[2];
    let det_r = (k[0] * rz[0] + k[1] * rz[1]) + k[2] * rz[2];
    let t2 = view.param * view.param;
    let zzz = z[0] * z[1] * z[2];
    fmath::div_rn(fmath::div_rn(det_r * triple, t2), zzz)
}

fn finite3(v: V3) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// The push constants `FaceSetupKernel::record` gives `face_setup.comp` for `settings`.
struct SetupConstants {
    dist: Dist,
    radius: f32,
    degenerate_k: f32,
    bary_margin: f32,
    pad_rel: f32,
}

impl SetupConstants {
    fn new(settings: &RasterSettings) -> Self {
        Self {
            dist: settings.dist,
            radius: if settings.dist == Dist::Hard {
                0.0
            } else {
                settings.cutoff().sqrt() as f32
            },
            degenerate_k: DEGENERATE_ULPS * f32::EPSILON,
            bary_margin: BARY_MARGIN,
            pad_rel: BBOX_PAD_REL,
        }
    }
}

/// `face_setup.comp`'s set-up of one face from its world vertices `q` and screen vertices `p`.
fn setup_face(view: &GpuView, pc: &SetupConstants, q: [V3; 3], p: [V3; 3]) -> GpuFaceSetup {
    let [p0, p1, p2] = p;
    let ta = (p1[0] - p0[0]) * (p2[1] - p0[1]);
    let tb = (p2[0] - p0[0]) * (p1[1] - p0[1]);
    let screen_det = ta - tb;
    let det = if view.projection == PROJ_MATRIX {
        screen_det
    } else {
        look_at_det(view, q, [p0[2], p1[2], p2[2]])
    };
    let clamped = if det > 0.0 {
        det.max(MIN_DET)
    } else {
        det.min(-MIN_DET)
    };
    let n = [
        [p1[1] - p2[1], p2[0] - p1[0], p1[0] * p2[1] - p2[0] * p1[1]],
        [p2[1] - p0[1], p0[0] - p2[0], p2[0] * p0[1] - p0[0] * p2[1]],
        [p0[1] - p1[1], p1[0] - p0[0], p0[0] * p1[1] - p1[0] * p0[1]],
    ];
    let finite = finite3(p0) && finite3(p1) && finite3(p2);
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    let degenerate = !(screen_det.abs() > pc.degenerate_k * (ta.abs() + tb.abs()));
    let flags = (if det < 0.0 { FACE_FRONT } else { 0 })
        | (if finite { FACE_FINITE } else { 0 })
        | (if degenerate { FACE_DEGENERATE } else { 0 });
    let bbox = if degenerate || !finite {
        [
            f32::NEG_INFINITY,
            f32::NEG_INFINITY,
            f32::INFINITY,
            f32::INFINITY,
        ]
    } else {
        let x0 = p0[0].min(p1[0]).min(p2[0]);
        let y0 = p0[1].min(p1[1]).min(p2[1]);
        let x1 = p0[0].max(p1[0]).max(p2[0]);
        let y1 = p0[1].max(p1[1]).max(p2[1]);
        let r = pc.radius;
        let b = match pc.dist {
            Dist::Euclidean => [x0 - r, y0 - r, x1 + r, y1 + r],
            Dist::Hard => [x0, y0, x1, y1],
            Dist::Barycentric => {
                let sc = fmath::div(det.abs(), MIN_DET).min(1.0);
                let k = 1.0 + fmath::div(3.0 * r * pc.bary_margin, sc);
                let cx = fmath::div(p0[0] + p1[0] + p2[0], 3.0);
                let cy = fmath::div(p0[1] + p1[1] + p2[1], 3.0);
                [
                    cx + k * (x0 - cx),
                    cy + k * (y0 - cy),
                    cx + k * (x1 - cx),
                    cy + k * (y1 - cy),
                ]
            }
        };
        let mag = x0.abs().max(x1.abs()).max(y0.abs().max(y1.abs())).max(1.0);
        let pad = pc.pad_rel * mag;
        [b[0] - pad, b[1] - pad, b[2] + pad, b[3] + pad]
    };
    let (inv_z, inv_len2, inv_det) = reciprocals(&p, det);
    GpuFaceSetup {
        v: [0, 1, 2].map(|k| [p[k][0], p[k][1], p[k][2], inv_z[k]]),
        inv: [0, 1, 2].map(|k| {
            let r = n[k].map(|x| fmath::div_rn(x, clamped));
            [r[0], r[1], r[2], inv_len2[k]]
        }),
        bbox,
        flags,
        mesh: view.mesh,
        det,
        inv_det,
    }
}

/// The face set-ups the device's forward writes (`GpuScene::read_setups`), view-major, from
/// the world positions of the views' meshes (`positions[m]`: mesh `m` of a batch), the faces
/// and the views ([`GpuView::new`] of each camera: the kernels' input, rounded from the host's
/// f64 look-at), with `settings`' distance, σ and ε_d: every vertex projected once per view
/// (`vertex_project.comp`), then every face set up from its corners (`face_setup.comp`).
pub fn face_setups(
    positions: &[&[[f32; 3]]],
    faces: &[[u32; 3]],
    views: &[GpuView],
    settings: &RasterSettings,
) -> Vec<GpuFaceSetup> {
    let pc = SetupConstants::new(settings);
    let mut out = Vec::with_capacity(views.len() * faces.len());
    for view in views {
        let world = positions[view.mesh as usize];
        let screen: Vec<V3> = world.iter().map(|&q| to_screen(view, q)).collect();
        for face in faces {
            let q = face.map(|v| world[v as usize]);
            let p = face.map(|v| screen[v as usize]);
            out.push(setup_face(view, &pc, q, p));
        }
    }
    out
}
