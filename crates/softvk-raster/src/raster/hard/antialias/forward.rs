//! The forward: which pixel pairs a silhouette edge blends (the pair analysis, in the module
//! docs' order) and the blend itself, with the screen-space helpers both directions use.

use super::{AntialiasInput, CROSSING_SLACK, EDGE_ENDS, EdgePair, ImageShape, TopologyHash};
/// The pixel pairs that `antialias` blends, in the order it visits them (see the module docs):
/// the forward's decisions, for tests and for comparing with the GPU's work list.
pub fn find_edge_pairs(
    input: &AntialiasInput,
    topology: Option<&TopologyHash>,
) -> Result<Vec<EdgePair>, String> {
    input.validate()?;
    let built;
    let hash = match topology {
        Some(h) if h.triangle_count() != input.tri.len() => {
            return Err(format!(
                "antialias: topology hash built from {} triangles, tri has {}",
                h.triangle_count(),
                input.tri.len()
            ));
        }
        Some(h) => h,
        None => {
            built = TopologyHash::new(input.tri);
            &built
        }
    };
    let s = input.shape;
    let mut pairs = Vec::new();
    for b in 0..s.batch {
        for y in 0..s.height {
            for x in 0..s.width {
                if x + 1 < s.width {
                    pairs.extend(analyse_pair(input, hash, b, x, y, false));
                }
                if y + 1 < s.height {
                    pairs.extend(analyse_pair(input, hash, b, x, y, true));
                }
            }
        }
    }
    Ok(pairs)
}

/// nvdiffrast's `antialias` forward: `color` with every silhouette-crossed pixel pair blended
/// (same shape as `color`). Without `topology`, the adjacency is built from `tri` for the call.
pub fn antialias(
    input: &AntialiasInput,
    topology: Option<&TopologyHash>,
) -> Result<Vec<f64>, String> {
    let pairs = find_edge_pairs(input, topology)?;
    let s = input.shape;
    let c = s.channels;
    let color = input.color;
    let mut out = color.to_vec();
    for pair in &pairs {
        let (p0, p1) = (pair.first_pixel(s), pair.second_pixel(s));
        let t = pair.target_pixel(s);
        for ch in 0..c {
            out[t * c + ch] += pair.alpha * (color[p1 * c + ch] - color[p0 * c + ch]);
        }
    }
    Ok(out)
}

/// Examines pair `(x, y)`–right (`vertical` false) or –next row (true) of item `b`; returns
/// its decisions if a silhouette edge blends it.
fn analyse_pair(
    input: &AntialiasInput,
    hash: &TopologyHash,
    b: usize,
    x: usize,
    y: usize,
    vertical: bool,
) -> Option<EdgePair> {
    let s = input.shape;
    let p0 = (b * s.height + y) * s.width + x;
    let p1 = p0 + if vertical { s.width } else { 1 };
    let (id0, id1) = (input.rast[4 * p0 + 3], input.rast[4 * p1 + 3]);
    if id0 == id1 {
        return None;
    }
    let (t0, t1) = (id0 as i64 - 1, id1 as i64 - 1);
    let chosen = if t0 >= 0 && t1 >= 0 {
        if input.rast[4 * p0 + 2] < input.rast[4 * p1 + 2] {
            t0
        } else {
            t1
        }
    } else if t0 >= 0 {
        t0
    } else {
        t1
    };
    if chosen < 0 || chosen as usize >= input.tri.len() {
        return None;
    }
    let mut pair = EdgePair {
        batch: b,
        x,
        y,
        vertical,
        from_second: chosen == t1,
        triangle: chosen as usize,
        edge: 0,
        alpha: 0.0,
    };
    let (cx, cy) = pair.triangle_pixel();
    let verts = input.tri[pair.triangle];
    let base = input.vertex_base(b);
    let q = verts.map(|v| pixel_frame(input.vertex(base + v as usize), cx, cy, s));

    // Silhouette test per edge, before the swap (it is a 2D side test, frame-independent).
    let own_area = signed_area(q[0], q[1], q[2]);
    let silhouette = EDGE_ENDS.map(|(i, j)| {
        let own = 3 - i - j;
        match hash.opposite_vertex(verts[i], verts[j], verts[own]) {
            // (A hash built from another mesh could name a vertex that is not there.)
            Some(o) if o as usize >= input.vertex_count() => true,
            None => true,
            Some(o) => {
                let qo = pixel_frame(input.vertex(base + o as usize), cx, cy, s);
                same_sign_bit(signed_area(qo, q[i], q[j]), own_area)
            }
        }
    });

    let q = if vertical { q.map(|[u, v]| [v, u]) } else { q };
    let sigma = if pair.from_second { -1.0 } else { 1.0 };
    // Per edge: whether it straddles the axis through the two centres, its crossing with it
    // as numerator / denominator (the denominator is the edge's extent across the pair, Δy),
    // and its extent along the pair (Δx).
    let straddles = EDGE_ENDS.map(|(i, j)| !same_sign_bit(q[i][1], q[j][1]));
    let num = EDGE_ENDS.map(|(i, j)| {
        let (a, e) = (q[i], q[j]);
        sigma * (a[0] * (e[1] - a[1]) - a[1] * (e[0] - a[0]))
    });
    let den = EDGE_ENDS.map(|(i, j)| q[j][1] - q[i][1]);
    let along = EDGE_ENDS.map(|(i, j)| q[j][0] - q[i][0]);
    // Edge m's crossing lies farther toward the other pixel than edge n's; an edge that does
    // not straddle has no crossing and loses to any that does.
    let beats = |m: usize, n: usize| {
        straddles[m] && (!straddles[n] || fraction_greater(num[m], den[m], num[n], den[n]))
    };
    let k = if beats(2, 0) && beats(2, 1) {
        2
    } else if beats(1, 0) {
        1
    } else {
        0
    };
    if !straddles[k] || !silhouette[k] || den[k].abs() < along[k].abs() {
        return None;
    }
    let reach = num[k] / den[k];
    if !(reach > -CROSSING_SLACK && reach < 1.0 + CROSSING_SLACK) {
        return None;
    }
    pair.edge = k;
    pair.alpha = sigma * (0.5 - reach.clamp(0.0, 1.0));
    Some(pair)
}

/// A clip-space vertex in pixel units relative to the centre of pixel `(cx, cy)`.
pub(super) fn pixel_frame(p: [f64; 4], cx: usize, cy: usize, s: ImageShape) -> [f64; 2] {
    let (hx, hy) = (0.5 * s.width as f64, 0.5 * s.height as f64);
    let inv_w = 1.0 / p[3];
    [
        p[0] * inv_w * hx - (cx as f64 + 0.5 - hx),
        p[1] * inv_w * hy - (cy as f64 + 0.5 - hy),
    ]
}

/// Twice the signed area of triangle `(a, b, c)`, measured from `a`.
fn signed_area(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
}

/// Whether two numbers have the same sign bit (so +0 and −0 differ, as in nvdiffrast).
fn same_sign_bit(a: f64, b: f64) -> bool {
    a.is_sign_negative() == b.is_sign_negative()
}

/// Whether `na/da > nb/db`, by cross-multiplying (no division, so zero denominators give an
/// answer); when the denominators' signs differ the comparison flips, and then equal fractions
/// count as greater (nvdiffrast's tie rule).
fn fraction_greater(na: f64, da: f64, nb: f64, db: f64) -> bool {
    let greater = na * db > nb * da;
    if same_sign_bit(da, db) {
        greater
    } else {
        !greater
    }
}
