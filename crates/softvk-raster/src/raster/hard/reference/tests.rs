//! Tests of the rasterizer's twin: coverage at pixel centres, the near and far planes, depth
//! ties and peeling, and the duals and `interpolate`'s backward against central differences.

use super::super::Topology;
use super::*;

fn shape(width: u32, height: u32, vertex_count: u32, triangle_count: u32) -> Shape {
    Shape {
        width,
        height,
        vertex_count,
        triangle_count,
        topology: Topology::Instanced { batch: 1 },
    }
}

/// An n×n grid of quads over `[-s, s]²` at depth `z`, each split along a diagonal that
/// alternates, as clip-space vertices with w = 1.
fn grid(n: u32, s: f64, z: f64) -> (Vec<f64>, Vec<[u32; 3]>) {
    let mut pos = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let x = -s + 2.0 * s * f64::from(i) / f64::from(n);
            let y = -s + 2.0 * s * f64::from(j) / f64::from(n);
            pos.extend([x, y, z, 1.0]);
        }
    }
    let mut tri = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let v = |di: u32, dj: u32| (j + dj) * (n + 1) + i + di;
            if (i + j) % 2 == 0 {
                tri.push([v(0, 0), v(1, 0), v(1, 1)]);
                tri.push([v(0, 0), v(1, 1), v(0, 1)]);
            } else {
                tri.push([v(0, 0), v(1, 0), v(0, 1)]);
                tri.push([v(1, 0), v(1, 1), v(0, 1)]);
            }
        }
    }
    (pos, tri)
}

fn clip(pos: &[f64], t: [u32; 3]) -> [Clip; 3] {
    t.map(|v| {
        let o = 4 * v as usize;
        [pos[o], pos[o + 1], pos[o + 2], pos[o + 3]]
    })
}

#[test]
fn edges_through_pixel_centres_draw_each_centre_once() {
    // 8×8 image, grid vertices on pixel centres: every inner edge passes through centres,
    // so only the fill rule decides them. Each centre inside the grid's square must be
    // covered by exactly one triangle (counted by brute force over all triangles).
    let (w, h) = (8, 8);
    // Pixel centres at NDC (2x + 1)/8 − 1: x = 1 → −0.625, x = 6 → 0.625.
    let (pos, tri) = grid(5, 0.625, 0.5);
    let drawn: Vec<Snapped> = tri
        .iter()
        .map(|&t| match coverage(clip(&pos, t), w, h) {
            Some(Coverage::Snapped(q)) => q,
            other => panic!("triangle {t:?}: {other:?}"),
        })
        .collect();
    let mut edge_hits = 0;
    for y in 0..h {
        for x in 0..w {
            let s = sample(x, y, w, h);
            let count = drawn.iter().filter(|q| q.covers(s)).count();
            // The square's left and bottom sides (centres x = 1, y = 1) are in, its right
            // and top sides (x = 6, y = 6) out.
            let inside = (1..6).contains(&x) && (1..6).contains(&y);
            assert_eq!(count, usize::from(inside), "pixel ({x}, {y})");
            edge_hits += drawn
                .iter()
                .filter(|q| (0..3).any(|k| edge_function(q.p[k], q.p[(k + 1) % 3], s) == 0))
                .count();
        }
    }
    assert!(
        edge_hits > 30,
        "the grid puts centres on edges ({edge_hits})"
    );
    // The rule on one triangle: its left and bottom edges are in, the third out.
    let one = Snapped::new([[0, 0], [32, 0], [0, 32]], false).unwrap();
    assert!(one.covers([0, 16]), "left edge is in");
    assert!(one.covers([16, 0]), "bottom edge is in");
    assert!(
        !one.covers([16, 16]),
        "the hypotenuse (going up-left) is out"
    );
    // Clockwise, the same triangle covers the same centres.
    let cw = Snapped::new([[0, 0], [0, 32], [32, 0]], false).unwrap();
    assert!(cw.covers([0, 16]) && cw.covers([16, 0]) && !cw.covers([16, 16]));
}

/// Sutherland–Hodgman against `w + z ≥ 0` (the near plane), for the test below.
fn clip_near(tri: &[Clip; 3]) -> Vec<Clip> {
    let d = |v: &Clip| v[3] + v[2];
    let mut out = Vec::new();
    for i in 0..3 {
        let (a, b) = (tri[i], tri[(i + 1) % 3]);
        if d(&a) >= 0.0 {
            out.push(a);
        }
        if (d(&a) >= 0.0) != (d(&b) >= 0.0) {
            let t = d(&a) / (d(&a) - d(&b));
            out.push(std::array::from_fn(|k| a[k] + t * (b[k] - a[k])));
        }
    }
    out
}

#[test]
fn a_triangle_through_the_near_plane_is_drawn_where_its_front_part_projects() {
    // One vertex behind the eye (w < 0): the homogeneous test must draw exactly the centres
    // inside the projection of the part in front of the near plane (clipped here by
    // Sutherland–Hodgman and tested in 2D), away from that polygon's edges.
    let (w, h) = (16, 12);
    let tri = [
        [-0.8, -0.7, 0.2, 1.0],
        [0.9, -0.6, 0.5, 1.2],
        [0.1, 0.9, -2.0, -0.5],
    ];
    assert_eq!(coverage(tri, w, h), Some(Coverage::Homogeneous));
    let poly: Vec<[f64; 2]> = clip_near(&tri)
        .iter()
        .map(|v| [v[0] / v[3], v[1] / v[3]])
        .collect();
    assert_eq!(poly.len(), 4);
    let mut drawn = 0;
    let mut near_edge = 0;
    for y in 0..h {
        for x in 0..w {
            let f = pixel_ndc(x, y, w, h);
            // Signed distances (NDC) to the polygon's edges, any winding.
            let n = poly.len();
            let d: Vec<f64> = (0..n)
                .map(|k| {
                    let (a, b) = (poly[k], poly[(k + 1) % n]);
                    let e = (b[0] - a[0]) * (f[1] - a[1]) - (b[1] - a[1]) * (f[0] - a[0]);
                    e / (b[0] - a[0]).hypot(b[1] - a[1])
                })
                .collect();
            if d.iter().any(|e| e.abs() < 1e-3) {
                near_edge += 1;
                continue;
            }
            let inside = d.iter().all(|&e| e > 0.0) || d.iter().all(|&e| e < 0.0);
            assert_eq!(homogeneous_covers(&tri, f), inside, "pixel ({x}, {y})");
            drawn += usize::from(inside);
        }
    }
    assert!(drawn > 20, "{drawn} pixels drawn");
    assert!(near_edge < 5, "{near_edge} pixels near an edge");
}

#[test]
fn a_triangle_beyond_one_plane_is_not_drawn_and_one_past_the_far_plane_is_cut() {
    let behind = [
        [0.0, 0.0, -2.0, -1.0],
        [0.5, 0.0, -2.0, -1.0],
        [0.0, 0.5, -2.0, -1.5],
    ];
    assert_eq!(coverage(behind, 8, 8), None);
    // Depth from −0.5 (left) to 3 (right): only the part with z/w ≤ 1 is drawn.
    let far = [
        [-1.0, -1.0, -0.5, 1.0],
        [1.0, -1.0, 3.0, 1.0],
        [-1.0, 1.0, -0.5, 1.0],
    ];
    assert_eq!(coverage(far, 8, 8), Some(Coverage::Homogeneous));
    for x in 0..8 {
        let f = pixel_ndc(x, 0, 8, 8);
        let z = -0.5 + 3.5 * (f[0] + 1.0) / 2.0;
        assert_eq!(homogeneous_covers(&far, f), z <= 1.0, "column {x}");
    }
}

#[test]
fn equal_depths_go_to_the_later_triangle_and_peeling_returns_both() {
    // Two triangles with the same vertices: the later (id 1) wins, the next layer is id 0,
    // and the layer after that is empty.
    let pos = vec![
        -0.9, -0.9, 0.1, 1.0, 0.9, -0.9, 0.1, 1.0, 0.0, 0.9, 0.1, 1.0,
    ];
    let tri = [[0, 1, 2], [0, 1, 2]];
    let sh = shape(8, 8, 3, 2);
    let first = rasterize(&sh, &pos, &tri, None);
    let centre = 4 * 8 + 4;
    assert_eq!(first.rast[4 * centre + 3], 2.0);
    let second = rasterize(&sh, &pos, &tri, Some(&first.keys));
    assert_eq!(second.rast[4 * centre + 3], 1.0);
    assert_eq!(
        second.rast[4 * centre..4 * centre + 3],
        first.rast[4 * centre..4 * centre + 3]
    );
    let third = rasterize(&sh, &pos, &tri, Some(&second.keys));
    assert!(third.rast.iter().all(|&v| v == 0.0));
}

#[test]
fn shade_duals_match_central_differences() {
    let c: [Clip; 3] = [
        [-0.6, -0.5, 0.1, 1.1],
        [0.7, -0.4, 0.3, 0.9],
        [0.05, 0.8, 0.2, 1.3],
    ];
    let f = [0.1, -0.05];
    let xyw: [[Dual<9>; 3]; 3] = std::array::from_fn(|k| {
        std::array::from_fn(|m| Dual::input(c[k][[0, 1, 3][m]], 3 * k + m))
    });
    let sh = shade(xyw, c.map(|v| v[2]), f, 32, 24);
    let h = 1e-6;
    let mut worst: f64 = 0.0;
    for input in 0..9 {
        let at = |d: f64| {
            let mut q = c;
            q[input / 3][[0, 1, 3][input % 3]] += d;
            let s = shade_f64(&q, f, 32, 24);
            [s.uv[0], s.uv[1], s.db[0], s.db[1], s.db[2], s.db[3]]
        };
        let (p, m) = (at(h), at(-h));
        let duals = [sh.uv[0], sh.uv[1], sh.db[0], sh.db[1], sh.db[2], sh.db[3]];
        for o in 0..6 {
            let fd = (p[o] - m[o]) / (2.0 * h);
            worst = worst.max((fd - duals[o].grad[input]).abs());
        }
    }
    assert!(worst < 1e-7, "worst |dual − central difference| {worst:e}");
}

#[test]
fn interpolate_grad_matches_central_differences() {
    let (pos, tri) = grid(2, 0.8, 0.3);
    let sh = shape(6, 5, 9, tri.len() as u32);
    let layer = rasterize(&sh, &pos, &tri, None);
    let layout = AttrLayout {
        vertex_count: 9,
        attr_count: 2,
        per_item: false,
    };
    let attr: Vec<f64> = (0..18).map(|i| (f64::from(i) * 0.37).sin()).collect();
    let diff = [1u32, 0];
    let pixels = 30;
    let dy: Vec<f64> = (0..pixels * 2).map(|i| (i as f64 * 0.11).cos()).collect();
    let dda: Vec<f64> = (0..pixels * 4).map(|i| (i as f64 * 0.23).sin()).collect();
    let loss = |attr: &[f64], rast: &[f64], db: &[f64]| {
        let (o, da) = interpolate(attr, layout, rast, &tri, pixels, Some(db), &diff);
        o.iter().zip(&dy).map(|(a, b)| a * b).sum::<f64>()
            + da.iter().zip(&dda).map(|(a, b)| a * b).sum::<f64>()
    };
    let g = interpolate_grad(
        &attr,
        layout,
        &layer.rast,
        &tri,
        pixels,
        Some(&layer.rast_db),
        &diff,
        &dy,
        Some(&dda),
    );
    let h = 1e-6;
    let fd = |v: &mut Vec<f64>, i: usize, which: u8| {
        let base = v[i];
        let eval = |d: f64, v: &mut Vec<f64>| {
            v[i] = base + d;
            let r = match which {
                0 => loss(v, &layer.rast, &layer.rast_db),
                1 => loss(&attr, v, &layer.rast_db),
                _ => loss(&attr, &layer.rast, v),
            };
            v[i] = base;
            r
        };
        (eval(h, v) - eval(-h, v)) / (2.0 * h)
    };
    let mut worst: f64 = 0.0;
    let mut a = attr.clone();
    for i in 0..a.len() {
        worst = worst.max((fd(&mut a, i, 0) - g.attr[i]).abs());
    }
    let mut r = layer.rast.clone();
    let mut d = layer.rast_db.clone();
    for i in 0..4 * pixels {
        if i % 4 < 2 {
            worst = worst.max((fd(&mut r, i, 1) - g.rast[i]).abs());
        }
        worst = worst.max((fd(&mut d, i, 2) - g.rast_db[i]).abs());
    }
    assert!(
        worst < 1e-7,
        "worst |analytic − central difference| {worst:e}"
    );
    assert!(g.attr.iter().any(|&v| v != 0.0) && g.rast_db.iter().any(|&v| v != 0.0));
}
