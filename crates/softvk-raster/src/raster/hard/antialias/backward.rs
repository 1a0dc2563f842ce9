//! The backward: the colour gradient of every blended pair and the position gradient through
//! its edge's crossing, for fixed `rast`.

use super::find_edge_pairs;
use super::forward::pixel_frame;
use super::{
    AntialiasGrad, AntialiasInput, EDGE_ENDS, GRADIENT_DY_EPSILON, ImageShape, TopologyHash,
};
/// nvdiffrast's `antialias` backward: given `dy = dL/d(output)`, `dL/dcolor` and `dL/dpos`
/// (the latter times `pos_gradient_boost`), for fixed `rast`.
pub fn antialias_backward(
    input: &AntialiasInput,
    topology: Option<&TopologyHash>,
    dy: &[f64],
    pos_gradient_boost: f64,
) -> Result<AntialiasGrad, String> {
    backward_with_epsilon(input, topology, dy, pos_gradient_boost, GRADIENT_DY_EPSILON)
}

/// The backward with the `1/Δy` guard as a parameter: `GRADIENT_DY_EPSILON` is nvdiffrast's,
/// 0 gives the exact derivative of the forward (what the tests check against differences).
pub(super) fn backward_with_epsilon(
    input: &AntialiasInput,
    topology: Option<&TopologyHash>,
    dy: &[f64],
    pos_gradient_boost: f64,
    dy_epsilon: f64,
) -> Result<AntialiasGrad, String> {
    let pairs = find_edge_pairs(input, topology)?;
    if dy.len() != input.color.len() {
        return Err(format!(
            "antialias backward: dy has {} values, color has {}",
            dy.len(),
            input.color.len()
        ));
    }
    let s = input.shape;
    let c = s.channels;
    let color = input.color;
    let mut grad_color = dy.to_vec();
    let mut grad_pos = vec![0.0; input.pos.len()];
    for pair in &pairs {
        // +0.0 is the work list's "no blend" value in nvdiffrast; -0.0 is not.
        if pair.alpha.to_bits() == 0 {
            continue;
        }
        let (p0, p1) = (pair.first_pixel(s), pair.second_pixel(s));
        let t = pair.target_pixel(s);
        // dL/dα, accumulated while the colour gradient is passed to both pixels.
        let mut dl_dalpha = 0.0;
        for ch in 0..c {
            let g = dy[t * c + ch];
            dl_dalpha += g * (color[p1 * c + ch] - color[p0 * c + ch]);
            grad_color[p0 * c + ch] -= pair.alpha * g;
            grad_color[p1 * c + ch] += pair.alpha * g;
        }
        // A saturated α is a clamped r (the crossing distance): flat in the geometry.
        if dl_dalpha == 0.0 || pair.alpha.abs() >= 0.5 {
            continue;
        }
        let verts = input.tri[pair.triangle];
        let (ia, ib) = EDGE_ENDS[pair.edge];
        let base = input.vertex_base(pair.batch);
        let (va, vb) = (base + verts[ia] as usize, base + verts[ib] as usize);
        let (pa, pb) = (input.vertex(va), input.vertex(vb));
        let (cx, cy) = pair.triangle_pixel();
        let mut a = pixel_frame(pa, cx, cy, s);
        let mut b = pixel_frame(pb, cx, cy, s);
        if pair.vertical {
            a.swap(0, 1);
            b.swap(0, 1);
        }
        // x_c = (a_x Δy − a_y Δx)/Δy and α = σ/2 − x_c (unclamped), so dL/dx_c = −dL/dα.
        let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
        let inv = 1.0 / (ey + dy_epsilon.copysign(ey));
        let xc = (a[0] * ey - a[1] * ex) * inv;
        let g = -dl_dalpha;
        let mut ga = [g * b[1] * inv, g * (xc - b[0]) * inv];
        let mut gb = [-g * a[1] * inv, g * (a[0] - xc) * inv];
        if pair.vertical {
            ga.swap(0, 1);
            gb.swap(0, 1);
        }
        add_clip_gradient(&mut grad_pos, va, pa, ga, s);
        add_clip_gradient(&mut grad_pos, vb, pb, gb, s);
    }
    if pos_gradient_boost != 1.0 {
        for g in &mut grad_pos {
            *g *= pos_gradient_boost;
        }
    }
    Ok(AntialiasGrad {
        color: grad_color,
        pos: grad_pos,
    })
}

/// Adds the gradient `g` with respect to vertex `v`'s pixel-frame position to `grad_pos`, chained
/// through the projection to its clip X, Y and W (Z does not enter the projection).
fn add_clip_gradient(grad_pos: &mut [f64], v: usize, p: [f64; 4], g: [f64; 2], s: ImageShape) {
    let (hx, hy) = (0.5 * s.width as f64, 0.5 * s.height as f64);
    let inv_w = 1.0 / p[3];
    let gx = g[0] * hx * inv_w;
    let gy = g[1] * hy * inv_w;
    grad_pos[4 * v] += gx;
    grad_pos[4 * v + 1] += gy;
    grad_pos[4 * v + 3] -= (p[0] * gx + p[1] * gy) * inv_w;
}
