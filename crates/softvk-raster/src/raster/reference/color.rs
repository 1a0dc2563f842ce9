//! Face colours as the fine pass samples them: the mesh's colours lit once in world space,
//! then per pixel either the texel SoftRas's rule picks from a face's R×R texture or the vertex
//! colours interpolated with the clipped barycentrics.

use super::MeshF64;
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::raster::settings::ColorMode;

/// Slack, in ulp per unit of R, of the texel rule's tie test (see [`surface_texel_index`]): the
/// rounding of `(w̃0 + w̃1) R` is a few ulp of R, in f64 here and in f32 on the GPU.
pub const TEXEL_TIE_ULPS: f64 = 8.0;

/// Index of the texel SoftRas samples within a face's R×R texture (SPEC §2):
/// `a = ⌊w̃0 R⌋, b = ⌊w̃1 R⌋`, texel `b R + a` if `(w̃0 + w̃1) R − a − b ≤ 1`, else
/// `(R−1−b) R + (R−1−a)`.
///
/// `a` and `b` are clamped to R − 1: at a corner (`w̃0 = 1` or `w̃1 = 1`, common for clipped
/// pixels outside a vertex) SoftRas reads past the face's texels into the next face's; the
/// clamp picks the corner texel instead and changes nothing anywhere else.
///
/// The test `frac ≤ 1` is taken with a slack of [`TEXEL_TIE_ULPS`]` · R` ulp. On the face's edge
/// `w̃2 = 0` (every pixel of the soft halo beyond edge v0 v1 clips there) the exact `frac` is 1,
/// a tie that the rule sends to the lower texel; the rounded `w̃0 + w̃1` lands on either side of
/// 1, and the other branch is the *mirrored* texel `a R + b`. SoftRas's f32 kernel flips between
/// the two there; the slack makes the rule's own answer come out in f64 and f32 alike. Elsewhere
/// it only moves texel boundaries by that many ulp.
pub fn surface_texel_index(w_clip: &[f64; 3], res: u32) -> usize {
    let r = f64::from(res);
    let a = ((w_clip[0] * r) as u32).min(res - 1);
    let b = ((w_clip[1] * r) as u32).min(res - 1);
    let frac = (w_clip[0] + w_clip[1]) * r - f64::from(a) - f64::from(b);
    if frac <= 1.0 + TEXEL_TIE_ULPS * r * f64::EPSILON {
        (b * res + a) as usize
    } else {
        ((res - 1 - b) * res + (res - 1 - a)) as usize
    }
}

/// Lit colours in the form the pixel loop samples.
#[derive(Clone, Debug, PartialEq)]
pub enum FaceColors {
    /// Per-face R×R texels, face-major.
    Surface {
        /// R.
        res: u32,
        /// `F * R²` lit texels.
        texels: Vec<[f64; 3]>,
    },
    /// Per-vertex lit colours and the faces that index them.
    Vertex {
        /// The mesh's faces.
        faces: Vec<[u32; 3]>,
        /// One lit colour per vertex.
        colors: Vec<[f64; 3]>,
    },
}

impl FaceColors {
    /// Lights the mesh's colours for the given mode.
    pub fn new(mesh: &Mesh, lighting: &Lighting, mode: ColorMode) -> FaceColors {
        FaceColors::of(&MeshF64::from_mesh(mesh), lighting, mode)
    }

    /// [`FaceColors::new`] of an f64 mesh.
    pub fn of(mesh: &MeshF64, lighting: &Lighting, mode: ColorMode) -> FaceColors {
        match mode {
            ColorMode::Surface => FaceColors::Surface {
                res: mesh.texture_res,
                texels: lighting.apply_surface_of(
                    &mesh.positions,
                    &mesh.faces,
                    mesh.texture_res,
                    &mesh.textures,
                ),
            },
            ColorMode::Vertex => FaceColors::Vertex {
                faces: mesh.faces.clone(),
                colors: lighting.apply_vertex_of(
                    &mesh.positions,
                    &mesh.faces,
                    mesh.vertex_colors.as_deref(),
                ),
            },
        }
    }

    /// `C_j` at clipped barycentrics `w̃`.
    pub fn sample(&self, face: usize, w_clip: &[f64; 3]) -> [f64; 3] {
        match self {
            FaceColors::Surface { res, texels } => {
                let r2 = (res * res) as usize;
                texels[face * r2 + surface_texel_index(w_clip, *res)]
            }
            FaceColors::Vertex { faces, colors } => {
                let c = faces[face].map(|v| colors[v as usize]);
                std::array::from_fn(|k| {
                    w_clip[0] * c[0][k] + w_clip[1] * c[1][k] + w_clip[2] * c[2][k]
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::coverage::clip_barycentric;
    use super::*;
    use crate::mesh::texel_center_barycentric;

    #[test]
    fn surface_texel_rule_inverts_the_texel_layout() {
        for res in 1..=8 {
            for i in 0..res * res {
                let w = texel_center_barycentric(res, i % res, i / res);
                assert_eq!(
                    surface_texel_index(&w, res),
                    i as usize,
                    "res {res} texel {i}"
                );
            }
        }
        // Corners read the corner texel, never past the face.
        for res in 1..=4 {
            assert_eq!(
                surface_texel_index(&[1.0, 0.0, 0.0], res),
                (res - 1) as usize
            );
            assert_eq!(
                surface_texel_index(&[0.0, 1.0, 0.0], res),
                ((res - 1) * res) as usize
            );
            assert_eq!(surface_texel_index(&[0.0, 0.0, 1.0], res), 0);
        }
    }

    /// Beyond edge v0 v1 every pixel clips to `w̃2 = 0`, where the rule's `frac` is exactly 1 and
    /// picks the lower texel; the rounded `w̃0 + w̃1` often lands just above 1, which without the
    /// tie slack would pick the mirrored texel `a R + b`.
    #[test]
    fn surface_texel_rule_keeps_the_lower_texel_on_the_edge_w2_0() {
        let mut rounded_above = 0;
        for i in 1..2000 {
            let c0 = f64::from(i) * 0.000_731_3;
            let w = clip_barycentric([c0, 1.3 - c0, -0.2]);
            assert_eq!(w[2], 0.0);
            rounded_above += usize::from(w[0] + w[1] > 1.0);
            for res in [2u32, 3, 5, 64] {
                let r = f64::from(res);
                let a = ((w[0] * r) as u32).min(res - 1);
                let b = ((w[1] * r) as u32).min(res - 1);
                assert_eq!(
                    surface_texel_index(&w, res),
                    (b * res + a) as usize,
                    "{w:?} R={res}"
                );
            }
        }
        assert!(
            rounded_above > 0,
            "the loop should hit the rounding it guards against"
        );
    }
}
