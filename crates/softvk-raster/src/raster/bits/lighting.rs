//! The bit twins of the scene's lit colours, both ways a scene gets them:
//!
//! - [`host_lit_colors`]: [`Renderer::prepare`](crate::raster::gpu::Renderer::prepare) lights
//!   on the host in f64 ([`Lighting::apply_surface`] / [`Lighting::apply_vertex`], SoftRas's
//!   order: lighting before projection) and rounds to f32: no device stage, the same f64
//!   functions rounded, so what it pins is the upload (layout and rounding);
//! - [`GpuLightTwin`]: the lighting kernels of [`SceneLight`](crate::raster::light::SceneLight)
//!   (what the pose fits record), `light_forward.comp` and the backward's `light_backward.comp`
//!   and `light_gather.comp` (`lighting.glsl`, `light_io.glsl`), in f32 operation for
//!   operation with [`crate::fmath`]'s square root and divisions.

use super::V3;
use crate::fmath;
use crate::lighting::{Lighting, NORMAL_EPS};
use crate::mesh::Mesh;
use crate::raster::reference_grad::VertexFaces;
use crate::raster::settings::ColorMode;

/// The colours [`Renderer::prepare`](crate::raster::gpu::Renderer::prepare) uploads to
/// `GpuScene::colors` for `mesh` under `lighting`: the host's f64 lighting rounded to f32, RGB
/// and an unused zero each.
pub fn host_lit_colors(mesh: &Mesh, lighting: &Lighting, mode: ColorMode) -> Vec<[f32; 4]> {
    let lit = match mode {
        ColorMode::Surface => lighting.apply_surface(mesh),
        ColorMode::Vertex => lighting.apply_vertex(mesh),
    };
    lit.iter()
        .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32, 0.0])
        .collect()
}

fn sub3(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn add3(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn mul3(a: V3, b: V3) -> V3 {
    [a[0] * b[0], a[1] * b[1], a[2] * b[2]]
}

fn scale3(a: V3, s: f32) -> V3 {
    a.map(|x| x * s)
}

fn div3(a: V3, b: f32) -> V3 {
    a.map(|x| fmath::div(x, b))
}

/// `fm_cross`.
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

const EPS: f32 = NORMAL_EPS as f32;

/// `normalize_eps` of `lighting.glsl`.
fn normalize_eps(v: V3) -> V3 {
    div3(v, fmath::length3(v).max(EPS))
}

/// `normalize_eps_grad` of `lighting.glsl`.
fn normalize_eps_grad(v: V3, g: V3) -> V3 {
    let len = fmath::length3(v);
    if len > EPS {
        let n = div3(v, len);
        return div3(sub3(g, scale3(n, fmath::dot3(n, g))), len);
    }
    div3(g, EPS)
}

/// The lighting kernels in f32 for one mesh (one scene's lights, unlit colours and faces).
pub struct GpuLightTwin<'a> {
    positions: &'a [[f32; 3]],
    faces: &'a [[u32; 3]],
    vertex_mode: bool,
    texels: usize,
    /// `SceneLight`'s unlit colours: surface texels, or vertex colours (white without).
    base: Vec<V3>,
    /// Ambient `I_a c_a`, then (direction, `I_l c_l`) per directional light, rounded to f32.
    ambient: V3,
    directionals: Vec<(V3, V3)>,
    incidence: VertexFaces,
}

impl<'a> GpuLightTwin<'a> {
    /// The twin of `SceneLight::new` for a scene of `mesh` under `lighting` in `mode`, lit at the
    /// world positions `positions` (the scene's).
    pub fn new(
        mesh: &'a Mesh,
        positions: &'a [[f32; 3]],
        lighting: &Lighting,
        mode: ColorMode,
    ) -> Self {
        let vertex_mode = mode == ColorMode::Vertex;
        let base = if vertex_mode {
            match &mesh.vertex_colors {
                Some(cs) => cs.clone(),
                None => vec![[1.0; 3]; mesh.positions.len()],
            }
        } else {
            mesh.textures.clone()
        };
        let f3 = |c: [f64; 3]| c.map(|x| x as f32);
        Self {
            positions,
            faces: &mesh.faces,
            vertex_mode,
            texels: (mesh.texture_res * mesh.texture_res) as usize,
            base,
            ambient: f3(lighting
                .ambient_color
                .map(|c| lighting.ambient_intensity * c)),
            directionals: lighting
                .directionals
                .iter()
                .map(|d| (f3(d.direction), f3(d.color.map(|c| d.intensity * c))))
                .collect(),
            incidence: VertexFaces::new(&mesh.faces, mesh.positions.len()),
        }
    }

    /// `raw_normal`: cross(p2 − p1, p0 − p1) of face `f`.
    fn raw_normal(&self, f: usize) -> V3 {
        let p = self.faces[f].map(|v| self.positions[v as usize]);
        cross(sub3(p[2], p[1]), sub3(p[0], p[1]))
    }

    /// `vertex_normal_sum`: the raw normals of the vertex's faces, in face order.
    fn vertex_normal_sum(&self, v: usize) -> V3 {
        let (b, e) = (
            self.incidence.offsets[v] as usize,
            self.incidence.offsets[v + 1] as usize,
        );
        self.incidence.slots[b..e]
            .iter()
            .fold([0.0; 3], |s, &slot| {
                add3(s, self.raw_normal(slot as usize / 3))
            })
    }

    /// `light_factor`.
    fn light_factor(&self, n: V3) -> V3 {
        self.directionals
            .iter()
            .fold(self.ambient, |l, &(dir, ic)| {
                add3(l, scale3(ic, fmath::dot3(n, dir).max(0.0)))
            })
    }

    /// `light_factor_grad`.
    fn light_factor_grad(&self, n: V3, d_light: V3) -> V3 {
        self.directionals.iter().fold([0.0; 3], |g, &(dir, ic)| {
            if fmath::dot3(n, dir) > 0.0 {
                add3(g, scale3(dir, fmath::dot3(ic, d_light)))
            } else {
                g
            }
        })
    }

    /// The lit colours `light_forward.comp` writes (`GpuScene::colors`' layout: RGB and an
    /// unused zero each).
    pub fn forward(&self) -> Vec<[f32; 4]> {
        let rgb0 = |c: V3| [c[0], c[1], c[2], 0.0];
        if self.vertex_mode {
            return (0..self.positions.len())
                .map(|v| {
                    let n = normalize_eps(self.vertex_normal_sum(v));
                    rgb0(mul3(self.base[v], self.light_factor(n)))
                })
                .collect();
        }
        let mut out = Vec::with_capacity(self.base.len());
        for f in 0..self.faces.len() {
            let l = self.light_factor(normalize_eps(self.raw_normal(f)));
            for t in f * self.texels..(f + 1) * self.texels {
                out.push(rgb0(mul3(self.base[t], l)));
            }
        }
        out
    }

    /// `write_corners`: dL/d(the face's corners) from dL/d(its raw normal).
    fn corners(&self, f: usize, g: V3) -> [V3; 3] {
        let p = self.faces[f].map(|v| self.positions[v as usize]);
        let a = sub3(p[2], p[1]);
        let b = sub3(p[0], p[1]);
        let g_a = cross(b, g);
        let g_b = cross(g, a);
        [g_b, sub3(g_a.map(|x| -x), g_b), g_a]
    }

    /// The lighting's backward as `SceneLight::record_backward` records it: from `d_lit`
    /// (dL/d(lit colour), what the raster backward writes) to dL/d(unlit colour)
    /// (`light_backward.comp`), and `d_positions` (the raster backward's dL/d(world position))
    /// plus the normals' share, each vertex's (face, corner) slots added in face order
    /// (`light_gather.comp`). Returns (dL/d(unlit colour), dL/d(world position)).
    pub fn backward(&self, d_lit: &[V3], d_positions: &[V3]) -> (Vec<V3>, Vec<V3>) {
        let nf = self.faces.len();
        let mut d_base = vec![[0.0f32; 3]; self.base.len()];
        let mut corners = vec![[0.0f32; 3]; 3 * nf];
        if self.vertex_mode {
            let d_sums: Vec<V3> = (0..self.positions.len())
                .map(|v| {
                    let sum = self.vertex_normal_sum(v);
                    let n = normalize_eps(sum);
                    let d = d_lit[v];
                    d_base[v] = mul3(d, self.light_factor(n));
                    let d_light = mul3(d, self.base[v]);
                    normalize_eps_grad(sum, self.light_factor_grad(n, d_light))
                })
                .collect();
            for f in 0..nf {
                let [a, b, c] = self.faces[f].map(|v| d_sums[v as usize]);
                let d_raw = add3(add3(a, b), c);
                corners[3 * f..3 * f + 3].copy_from_slice(&self.corners(f, d_raw));
            }
        } else {
            for f in 0..nf {
                let raw = self.raw_normal(f);
                let n = normalize_eps(raw);
                let l = self.light_factor(n);
                let mut d_light = [0.0f32; 3];
                for t in f * self.texels..(f + 1) * self.texels {
                    let d = d_lit[t];
                    d_base[t] = mul3(d, l);
                    d_light = add3(d_light, mul3(d, self.base[t]));
                }
                let g = normalize_eps_grad(raw, self.light_factor_grad(n, d_light));
                corners[3 * f..3 * f + 3].copy_from_slice(&self.corners(f, g));
            }
        }
        let positions = (0..self.positions.len())
            .map(|v| {
                let (b, e) = (
                    self.incidence.offsets[v] as usize,
                    self.incidence.offsets[v + 1] as usize,
                );
                let acc = self.incidence.slots[b..e]
                    .iter()
                    .fold([0.0; 3], |s, &slot| add3(s, corners[slot as usize]));
                add3(d_positions[v], acc)
            })
            .collect();
        (d_base, positions)
    }
}
