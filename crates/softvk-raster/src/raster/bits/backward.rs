//! The backward's sums: each face's per-pixel terms summed into partials in the device's
//! order ([`SumOrder`]), the partials reduced in unit order, then the world-space gradients
//! and their gather ([`FineTwin::backward`]).

use super::{Face, FineTwin, PairGrad, V3, add3, dot3, face_of};
use crate::fmath;
use crate::raster::fine::PixelAux;
use crate::raster::settings::ColorMode;
use crate::raster::setup::FACE_FINITE;
/// The gradients the device's backward writes (`GradIo::positions` and `GradIo::colors`): before
/// the host adds the lighting's share (exactly zero with an unlit lighting).
pub struct BackwardTwin {
    /// dL/d(world position) per vertex.
    pub positions: Vec<V3>,
    /// dL/d(lit colour) per texel slot (surface colours, face after face) or per vertex.
    pub colors: Vec<V3>,
}

impl FineTwin<'_> {
    /// The backward of views `0..views.len()` for `d_image` (output resolution, view-major),
    /// given the forward's rendered images and aux of each view ([`FineTwin::rendered`]:
    /// `rendered[v]`), the world positions (one mesh) and the views: each face's per-pixel terms
    /// summed into partials in `order` (the device's backward kernel for that method), the
    /// partials reduced in unit order (`grad_reduce.comp`, `grad_reduce_texels.comp`), then
    /// `grad_world.comp` and `grad_gather.comp`. The results are what the device writes to
    /// `GradIo::positions` and `GradIo::colors` (dL/d(lit colour)): with [`Lighting::unlit`]
    /// exactly what [`Renderer::backward`] returns, the host's f64 lighting share being zero.
    ///
    /// [`Lighting::unlit`]: crate::lighting::Lighting::unlit
    /// [`Renderer::backward`]: crate::raster::gpu::Renderer::backward
    pub fn backward(
        &self,
        views: &[crate::raster::setup::GpuView],
        positions: &[[f32; 3]],
        d_image: &[[f32; 4]],
        rendered: &[(Vec<[f32; 4]>, Vec<PixelAux>)],
        order: SumOrder,
    ) -> BackwardTwin {
        let pc = &self.push;
        let nf = pc.face_count as usize;
        let vertex_colors = self.settings.color_mode == ColorMode::Vertex;
        let slots = if vertex_colors {
            3
        } else {
            (pc.texture_res * pc.texture_res) as usize
        };
        // Per (view, face): the screen corners (and vertex colours) after `grad_reduce.comp`;
        // per (face, texel): the texel gradients after `grad_reduce_texels.comp`, one running
        // sum over the views in order and each view's units in order.
        let mut screen = vec![[[0.0f32; 3]; 3]; views.len() * nf];
        let mut colors = vec![
            [0.0f32; 3];
            if vertex_colors {
                views.len() * nf * slots
            } else {
                0
            }
        ];
        let mut texels = vec![[0.0f32; 3]; if vertex_colors { 0 } else { nf * slots }];
        for (v, (images, aux)) in rendered.iter().enumerate() {
            let setups = &self.inputs.setups[v * nf..(v + 1) * nf];
            for (j, setup) in setups.iter().enumerate() {
                let f = face_of(setup);
                // The pair's contribution at rendered pixel (col, row), where it has one.
                let pair = |col: u32, row: u32| -> Option<PairGrad> {
                    let id = (row * pc.width + col) as usize;
                    let u = self.upstream(v as u32, col, row, d_image, images[id], &aux[id]);
                    if u.d_alpha == 0.0 && (self.alpha_only || u.d_rgb == [0.0; 3]) {
                        return None;
                    }
                    self.pixel_face_grad(&f, j as u32, &u)
                };
                let units = match order {
                    SumOrder::Brute { band_rows } => self.brute_units(&f, slots, band_rows, pair),
                    SumOrder::Tiled { tile } => self.tiled_units(slots, tile, pair),
                };
                let item = v * nf + j;
                for unit in &units {
                    for (s, x) in screen[item].iter_mut().zip(unit.screen) {
                        add3(s, x);
                    }
                    if vertex_colors {
                        for (s, &x) in colors[item * slots..(item + 1) * slots]
                            .iter_mut()
                            .zip(&unit.colors)
                        {
                            add3(s, x);
                        }
                    } else {
                        let face_texels = &mut texels[j * slots..(j + 1) * slots];
                        for (t, s) in face_texels.iter_mut().enumerate() {
                            if unit.written[t] {
                                add3(s, unit.colors[t]);
                            }
                        }
                    }
                }
            }
        }
        // grad_world.comp: each corner's screen gradient to world space.
        let faces = self.inputs.faces;
        let mut corner_world = vec![[[0.0f32; 3]; 3]; views.len() * nf];
        for (v, view) in views.iter().enumerate() {
            for j in 0..nf {
                for c in 0..3 {
                    let g = screen[v * nf + j][c];
                    if g == [0.0; 3] {
                        continue;
                    }
                    let p = positions[faces[j][c] as usize];
                    corner_world[v * nf + j][c] = world_grad(view, p, g);
                }
            }
        }
        // grad_gather.comp: per vertex, its views in order, its (face, corner) slots in order.
        let nv = pc.vertex_count as usize;
        let adjacency = crate::raster::reference_grad::VertexFaces::new(faces, nv);
        let mut out_pos = vec![[0.0f32; 3]; nv];
        let mut out_col = if vertex_colors {
            vec![[0.0f32; 3]; nv]
        } else {
            texels
        };
        for vtx in 0..nv {
            let (b, e) = (
                adjacency.offsets[vtx] as usize,
                adjacency.offsets[vtx + 1] as usize,
            );
            for v in 0..views.len() {
                for &slot in &adjacency.slots[b..e] {
                    let (face, corner) = ((slot / 3) as usize, (slot % 3) as usize);
                    let w = corner_world[v * nf + face][corner];
                    add3(&mut out_pos[vtx], w);
                    if vertex_colors {
                        let c = colors[(v * nf + face) * slots + corner];
                        add3(&mut out_col[vtx], c);
                    }
                }
            }
        }
        BackwardTwin {
            positions: out_pos,
            colors: out_col,
        }
    }

    /// `grad_brute.comp`'s units of one (view, face): bands of `band_rows` rows from the top,
    /// each the running sum of its pixels' contributions in row-major order.
    fn brute_units(
        &self,
        f: &Face,
        slots: usize,
        band_rows: u32,
        pair: impl Fn(u32, u32) -> Option<PairGrad>,
    ) -> Vec<Partial> {
        let pc = &self.push;
        let vertex_colors = self.settings.color_mode == ColorMode::Vertex;
        let mut units = Vec::new();
        let mut row0 = 0;
        while row0 < pc.height {
            let mut unit = Partial::new(slots);
            if f.flags & FACE_FINITE != 0 {
                for row in row0..(row0 + band_rows).min(pc.height) {
                    for col in 0..pc.width {
                        let Some(g) = pair(col, row) else { continue };
                        for (acc, x) in unit.screen.iter_mut().zip(g.screen) {
                            add3(acc, x);
                        }
                        if g.colored {
                            if vertex_colors {
                                for (acc, x) in unit.colors.iter_mut().zip(g.color) {
                                    add3(acc, x);
                                }
                            } else {
                                add3(&mut unit.colors[g.texel as usize], g.color[0]);
                                unit.written[g.texel as usize] = true;
                            }
                        }
                    }
                }
            }
            units.push(unit);
            row0 += band_rows;
        }
        units
    }

    /// `grad_tiled.comp`'s units of one (view, face): one per `tile × tile` tile, tiles in
    /// row-major order (the order binning's scatter gives a face's entries). A tile's partial
    /// adds, one 2 × 2 quad after another in [`morton_pixel`]'s order, each quad's sum
    /// `(v0 + v1) + (v2 + v3)` of its pixels' contributions, a pixel with none adding -0.0;
    /// a texel slot adds its pixels' contributions one at a time in the same order. That order
    /// is the pixels', not the subgroup's or the workgroup's: the same bits at any subgroup
    /// size and workgroup shape. Every tile is a unit here, where the device has units only for
    /// the tiles binning gave the face: a tile without any contribution sums to +0.0, and adding
    /// +0.0 to a running sum that starts at +0.0 changes no bit (such a sum is never -0.0).
    fn tiled_units(
        &self,
        slots: usize,
        tile: u32,
        pair: impl Fn(u32, u32) -> Option<PairGrad>,
    ) -> Vec<Partial> {
        const NEG_ZERO: f32 = -0.0;
        let pc = &self.push;
        let vertex_colors = self.settings.color_mode == ColorMode::Vertex;
        let alpha_only = self.alpha_only;
        // With an alpha-only upstream the device adds only x and y of each corner.
        let axes = if alpha_only { 2 } else { 3 };
        let quad_sum = |v: [f32; 4]| (v[0] + v[1]) + (v[2] + v[3]);
        let mut units = Vec::new();
        for ty in 0..pc.height.div_ceil(tile) {
            for tx in 0..pc.width.div_ceil(tile) {
                let mut unit = Partial::new(slots);
                for quad in 0..tile * tile / 4 {
                    let g: [Option<PairGrad>; 4] = std::array::from_fn(|k| {
                        let (x, y) = morton_pixel(4 * quad + k as u32, tile);
                        let (col, row) = (tx * tile + x, ty * tile + y);
                        (col < pc.width && row < pc.height)
                            .then(|| pair(col, row))
                            .flatten()
                    });
                    for c in 0..3 {
                        for a in 0..axes {
                            let v = g
                                .each_ref()
                                .map(|g| g.as_ref().map_or(NEG_ZERO, |g| g.screen[c][a]));
                            unit.screen[c][a] += quad_sum(v);
                        }
                    }
                    if alpha_only {
                        continue;
                    }
                    fn colored(g: &Option<PairGrad>) -> Option<&PairGrad> {
                        g.as_ref().filter(|g| g.colored)
                    }
                    if vertex_colors {
                        for c in 0..3 {
                            for a in 0..3 {
                                let v = g
                                    .each_ref()
                                    .map(|g| colored(g).map_or(NEG_ZERO, |g| g.color[c][a]));
                                unit.colors[c][a] += quad_sum(v);
                            }
                        }
                    } else {
                        for g in g.iter().filter_map(colored) {
                            add3(&mut unit.colors[g.texel as usize], g.color[0]);
                            unit.written[g.texel as usize] = true;
                        }
                    }
                }
                units.push(unit);
            }
        }
        units
    }
}

/// One unit's partial gradient (a band of a face, or a (face, tile) entry): the screen corners,
/// the colour slots (3 vertex colours or R² texels) and which texel slots were written.
struct Partial {
    screen: [V3; 3],
    colors: Vec<V3>,
    written: Vec<bool>,
}

impl Partial {
    fn new(slots: usize) -> Self {
        Self {
            screen: [[0.0; 3]; 3],
            colors: vec![[0.0; 3]; slots],
            written: vec![false; slots],
        }
    }
}

/// `morton_pixel` of `subgroup_face.glsl`: where pixel `i` of a `size`-wide tile lies in the
/// tiled backward's order (8 × 8 blocks row-major; in a block the Z order of its 64 pixels).
pub fn morton_pixel(i: u32, size: u32) -> (u32, u32) {
    let block = i >> 6;
    let m = i & 63;
    let per_row = size / 8;
    let x = (m & 1) | ((m >> 1) & 2) | ((m >> 2) & 4);
    let y = ((m >> 1) & 1) | ((m >> 2) & 2) | ((m >> 3) & 4);
    ((block % per_row) * 8 + x, (block / per_row) * 8 + y)
}

/// The order in which a backward sums each face's per-pixel terms: the device's backward
/// kernel for each [`Method`](crate::raster::gpu::Method).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SumOrder {
    /// `grad_brute.comp` (`Method::Brute`): one unit per band of `band_rows` rows (the
    /// backward's band; the whole rendered height unless a driver's loop cap splits it), its
    /// pixels in row-major order.
    Brute {
        /// Rows per band.
        band_rows: u32,
    },
    /// `grad_tiled.comp` (`Method::Tiled`, the default): one unit per (face, tile), its pixels
    /// in [`morton_pixel`]'s order, summed a 2 × 2 quad at a time.
    Tiled {
        /// The forward's tile edge in pixels.
        tile: u32,
    },
}

/// `grad_world.comp` for a look-at view (perspective or orthographic).
fn world_grad(view: &crate::raster::setup::GpuView, p: V3, g: V3) -> V3 {
    use crate::raster::setup::PROJ_PERSPECTIVE;
    let row = |k: usize| [view.rows[k][0], view.rows[k][1], view.rows[k][2]];
    let rel = [p[0] - view.eye[0], p[1] - view.eye[1], p[2] - view.eye[2]];
    let pcam = [dot3(row(0), rel), dot3(row(1), rel), dot3(row(2), rel)];
    let d_cam = if view.projection == PROJ_PERSPECTIVE {
        let k_xy = fmath::rcp(pcam[2] * view.param);
        [
            g[0] * k_xy,
            g[1] * k_xy,
            g[2] - fmath::div((g[0] * pcam[0] + g[1] * pcam[1]) * k_xy, pcam[2]),
        ]
    } else {
        [g[0] * view.param, g[1] * view.param, g[2]]
    };
    let (r0, r1, r2) = (row(0), row(1), row(2));
    [0, 1, 2].map(|a| (r0[a] * d_cam[0] + r1[a] * d_cam[1]) + r2[a] * d_cam[2])
}
