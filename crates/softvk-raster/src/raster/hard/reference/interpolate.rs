//! nvdiffrast's `interpolate`, forward ([`interpolate`]) and backward ([`interpolate_grad`]):
//! the attributes at each pixel's barycentrics and their pixel derivatives.

use super::drawn_triangle;

/// Where `interpolate` finds a pixel's attribute rows: `attr [V, A]` shared by the minibatch
/// (also `[1, V, A]`, broadcast), or `[B, V, A]`, one set per item (instanced mode only).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AttrLayout {
    /// Vertices V.
    pub vertex_count: u32,
    /// Attributes A per vertex.
    pub attr_count: u32,
    /// One set of attributes per minibatch item.
    pub per_item: bool,
}

impl AttrLayout {
    fn row(&self, b: usize, v: u32) -> usize {
        let set = if self.per_item { b } else { 0 };
        set * self.vertex_count as usize + v as usize
    }
}

/// `interpolate` for `rast` `[B, H, W, 4]` (`pixels` = B·H·W): `out [B, H, W, A]` =
/// `u a_0 + v a_1 + (1 − u − v) a_2`, and with `diff` (the attributes to differentiate) and
/// `rast_db`, `out_da [B, H, W, 2N]`: `(∂a/∂X, ∂a/∂Y)` for each listed attribute in order.
/// Zero where nothing is drawn.
pub fn interpolate(
    attr: &[f64],
    layout: AttrLayout,
    rast: &[f64],
    tri: &[[u32; 3]],
    pixels_per_item: usize,
    rast_db: Option<&[f64]>,
    diff: &[u32],
) -> (Vec<f64>, Vec<f64>) {
    let pixels = rast.len() / 4;
    let a = layout.attr_count as usize;
    let mut out = vec![0.0; pixels * a];
    let mut out_da = vec![0.0; pixels * 2 * diff.len()];
    for i in 0..pixels {
        let Some(t) = drawn_triangle(rast, i, tri.len() as u32) else {
            continue;
        };
        let rows = tri[t as usize].map(|v| a * layout.row(i / pixels_per_item, v));
        let (u, v) = (rast[4 * i], rast[4 * i + 1]);
        let bary = [u, v, 1.0 - u - v];
        for j in 0..a {
            out[i * a + j] = (0..3).map(|k| bary[k] * attr[rows[k] + j]).sum();
        }
        if let Some(db) = rast_db {
            for (n, &j) in diff.iter().enumerate() {
                let j = j as usize;
                let du = attr[rows[0] + j] - attr[rows[2] + j];
                let dv = attr[rows[1] + j] - attr[rows[2] + j];
                let o = i * 2 * diff.len() + 2 * n;
                out_da[o] = db[4 * i] * du + db[4 * i + 2] * dv;
                out_da[o + 1] = db[4 * i + 1] * du + db[4 * i + 3] * dv;
            }
        }
    }
    (out, out_da)
}

/// The gradients of [`interpolate`]: to `attr`, to `rast` (channels 0 and 1) and, with
/// `rast_db` and `dda` (the upstream gradient of `out_da`), to `rast_db`.
pub struct InterpolateGrads {
    /// Same shape as `attr`.
    pub attr: Vec<f64>,
    /// `[B, H, W, 4]`.
    pub rast: Vec<f64>,
    /// `[B, H, W, 4]` (zero without `rast_db`).
    pub rast_db: Vec<f64>,
}

/// The backward of [`interpolate`] (it is linear in `attr` and in `u, v` and `rast_db`
/// separately, so each gradient is written out directly).
#[allow(clippy::too_many_arguments)]
pub fn interpolate_grad(
    attr: &[f64],
    layout: AttrLayout,
    rast: &[f64],
    tri: &[[u32; 3]],
    pixels_per_item: usize,
    rast_db: Option<&[f64]>,
    diff: &[u32],
    dy: &[f64],
    dda: Option<&[f64]>,
) -> InterpolateGrads {
    let pixels = rast.len() / 4;
    let a = layout.attr_count as usize;
    let mut g = InterpolateGrads {
        attr: vec![0.0; attr.len()],
        rast: vec![0.0; 4 * pixels],
        rast_db: vec![0.0; 4 * pixels],
    };
    for i in 0..pixels {
        let Some(t) = drawn_triangle(rast, i, tri.len() as u32) else {
            continue;
        };
        let rows = tri[t as usize].map(|v| a * layout.row(i / pixels_per_item, v));
        let (u, v) = (rast[4 * i], rast[4 * i + 1]);
        let bary = [u, v, 1.0 - u - v];
        for j in 0..a {
            let up = dy[i * a + j];
            for k in 0..3 {
                g.attr[rows[k] + j] += bary[k] * up;
            }
            g.rast[4 * i] += up * (attr[rows[0] + j] - attr[rows[2] + j]);
            g.rast[4 * i + 1] += up * (attr[rows[1] + j] - attr[rows[2] + j]);
        }
        let (Some(db), Some(dda)) = (rast_db, dda) else {
            continue;
        };
        let d = &db[4 * i..4 * i + 4];
        for (n, &j) in diff.iter().enumerate() {
            let j = j as usize;
            let o = i * 2 * diff.len() + 2 * n;
            let (gx, gy) = (dda[o], dda[o + 1]);
            // ∂a/∂X = du/dX (a0 − a2) + dv/dX (a1 − a2), likewise Y.
            let gdu = gx * d[0] + gy * d[1];
            let gdv = gx * d[2] + gy * d[3];
            g.attr[rows[0] + j] += gdu;
            g.attr[rows[1] + j] += gdv;
            g.attr[rows[2] + j] -= gdu + gdv;
            let du = attr[rows[0] + j] - attr[rows[2] + j];
            let dv = attr[rows[1] + j] - attr[rows[2] + j];
            g.rast_db[4 * i] += gx * du;
            g.rast_db[4 * i + 1] += gy * du;
            g.rast_db[4 * i + 2] += gx * dv;
            g.rast_db[4 * i + 3] += gy * dv;
        }
    }
    g
}
