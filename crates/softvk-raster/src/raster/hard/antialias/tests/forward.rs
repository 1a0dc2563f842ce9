//! The forward's tests: hand-computed blends, a closed mesh's silhouette, and the blend
//! factor against exact box coverage.

use super::super::backward::backward_with_epsilon;
use super::*;
// ---- 1. hand-computed blends ----

#[test]
fn vertical_edge_blends_the_pixel_whose_box_holds_the_crossing() {
    // W = 4, H = 2, C = 3; a triangle left of a vertical edge at pixel x = `edge`, drawn
    // at w = 2 (the projection divides it out). Pixel centres are at x = 0.5 .. 3.5.
    for (edge, target, other, share) in [(2.3, 2, 1, 0.3), (1.8, 1, 2, 0.2)] {
        let e = 2.0 * edge / 4.0 - 1.0;
        let w = 2.0;
        let clip = [[-10.0, -10.0], [e, -10.0], [e, 10.0]]
            .iter()
            .flat_map(|&[x, y]| [x * w, y * w, 0.1 * w, w])
            .collect();
        let mut scene = single_image(clip, vec![[0, 1, 2]], 4, 2, 3);
        for p in 0..8 {
            assert_eq!(id(&scene, p), if p % 4 < 2 { 1.0 } else { 0.0 });
        }
        scene.color = (0..24).map(|i| 0.1 + 0.37 * i as f64).collect();
        let out = antialias(&scene.input(), None).unwrap();
        for p in 0..8 {
            for ch in 0..3 {
                let c = |q: usize| scene.color[3 * q + ch];
                let row = p - p % 4;
                let expected = if p % 4 == target {
                    (1.0 - share) * c(p) + share * c(row + other)
                } else {
                    c(p)
                };
                assert!(
                    (out[3 * p + ch] - expected).abs() < 1e-12,
                    "edge {edge}, pixel {p}, channel {ch}: {} vs {expected}",
                    out[3 * p + ch]
                );
            }
        }
    }
}

#[test]
fn horizontal_edge_seen_from_the_upper_pixel_blends_the_upper_pixel() {
    // W = 2, H = 4; a triangle above a horizontal edge at pixel y = 1.3: rows 1..3 are
    // covered, row 0 is not, so each column's pair (row 0, row 1) takes the triangle from
    // its second pixel (σ = −1) and row 1's box, [1, 2], is 0.3 background.
    let e = 2.0 * 1.3 / 4.0 - 1.0;
    let clip = [[-10.0, e], [10.0, e], [0.0, 10.0]]
        .iter()
        .flat_map(|&[x, y]| [x, y, 0.0, 1.0])
        .collect();
    let mut scene = single_image(clip, vec![[0, 1, 2]], 2, 4, 1);
    scene.color = vec![0.25, 0.5, 2.0, 4.0, 2.5, 4.5, 3.0, 5.0];
    let pairs = find_edge_pairs(&scene.input(), None).unwrap();
    assert_eq!(pairs.len(), 2);
    for (x, pair) in pairs.iter().enumerate() {
        assert_eq!(
            (pair.x, pair.y, pair.vertical, pair.from_second),
            (x, 0, true, true)
        );
        assert_eq!((pair.triangle, pair.edge), (0, 2), "edge (v0, v1)");
        assert!((pair.alpha + 0.3).abs() < 1e-12, "alpha {}", pair.alpha);
    }
    let out = antialias(&scene.input(), None).unwrap();
    let c = &scene.color;
    let expected = [
        c[0],
        c[1],
        0.7 * c[2] + 0.3 * c[0],
        0.7 * c[3] + 0.3 * c[1],
        c[4],
        c[5],
        c[6],
        c[7],
    ];
    for (o, e) in out.iter().zip(expected) {
        assert!((o - e).abs() < 1e-12, "{out:?} vs {expected:?}");
    }
}

#[test]
fn nearer_triangle_supplies_the_edge_and_a_depth_tie_goes_to_the_second_pixel() {
    // W = 4, H = 1. Triangle A lies left of x = 2.3, triangle B right of x = 1.7; the
    // centres 1.5 and 2.5 see only A and only B. If A is nearer its edge at 2.3 blends
    // pixel 2 (0.3 of A's colour); if B is nearer (or the depths tie) its edge at 1.7
    // blends pixel 1 (0.3 of B's colour).
    let ndc = |px: f64| 2.0 * px / 4.0 - 1.0;
    for (za, zb, a_wins) in [(0.1, 0.4, true), (0.4, 0.1, false), (0.2, 0.2, false)] {
        let (ea, eb) = (ndc(2.3), ndc(1.7));
        let clip = [
            [-10.0, 0.0, za],
            [ea, -10.0, za],
            [ea, 10.0, za],
            [10.0, 0.0, zb],
            [eb, 10.0, zb],
            [eb, -10.0, zb],
        ]
        .iter()
        .flat_map(|&[x, y, z]| [x, y, z, 1.0])
        .collect();
        let mut scene = single_image(clip, vec![[0, 1, 2], [3, 4, 5]], 4, 1, 1);
        assert_eq!(
            (0..4).map(|p| id(&scene, p)).collect::<Vec<_>>(),
            [1.0, 1.0, 2.0, 2.0]
        );
        scene.color = vec![1.0, 3.0, 7.0, 15.0];
        let pairs = find_edge_pairs(&scene.input(), None).unwrap();
        assert_eq!(pairs.len(), 1);
        assert_eq!(pairs[0].triangle, if a_wins { 0 } else { 1 });
        assert_eq!(pairs[0].from_second, !a_wins);
        let out = antialias(&scene.input(), None).unwrap();
        let expected = if a_wins {
            [1.0, 3.0, 0.7 * 7.0 + 0.3 * 3.0, 15.0]
        } else {
            [1.0, 0.7 * 3.0 + 0.3 * 7.0, 7.0, 15.0]
        };
        for (o, e) in out.iter().zip(expected) {
            assert!(
                (o - e).abs() < 1e-12,
                "za {za} zb {zb}: {out:?} vs {expected:?}"
            );
        }
    }
}

#[test]
fn an_edge_is_a_silhouette_only_where_its_neighbour_folds_back() {
    // Triangle A = (v0, v1, v2) left of the vertical edge v1–v2 at pixel x = 2.3; triangle
    // B = (v2, v1, v3) shares that edge. Flat (v3 to the right) the edge is interior and
    // the pair (1, 2), A | B, is not blended; folded (v3 to the left, behind A) the pair
    // (1, 2), A | background, is.
    let e = 2.0 * 2.3 / 4.0 - 1.0;
    for (v3x, blended) in [(10.0, false), (-8.0, true)] {
        let clip = [
            [-10.0, 0.0, 0.1],
            [e, -10.0, 0.1],
            [e, 10.0, 0.1],
            [v3x, 0.5, 0.6],
        ]
        .iter()
        .flat_map(|&[x, y, z]| [x, y, z, 1.0])
        .collect();
        let scene = single_image(clip, vec![[0, 1, 2], [2, 1, 3]], 4, 1, 1);
        assert_eq!(id(&scene, 1), 1.0);
        assert_eq!(id(&scene, 2), if blended { 0.0 } else { 2.0 });
        let pairs = find_edge_pairs(&scene.input(), None).unwrap();
        assert_eq!(pairs.len(), usize::from(blended), "{pairs:?}");
        // Without the adjacency (two unrelated triangles) the edge always blends.
        let split = AntialiasInput {
            tri: &[[0, 1, 2], [2, 1, 3]],
            ..scene.input()
        };
        let apart = TopologyHash::new(&[[0, 1, 2], [4, 5, 3]]);
        assert_eq!(find_edge_pairs(&split, Some(&apart)).unwrap().len(), 1);
    }
}

#[test]
fn topology_hash_keeps_the_first_two_distinct_opposite_vertices() {
    // Edge (0, 1) is shared by three triangles: the first two (in triangle order) are
    // each other's opposite vertices, the third has none. Edge (1, 2) has one triangle. A triangle
    // with a repeated index is left out.
    let hash = TopologyHash::new(&[[0, 1, 2], [1, 0, 3], [0, 4, 1], [2, 2, 5]]);
    assert_eq!(hash.triangle_count(), 4);
    assert_eq!(hash.opposite_vertex(0, 1, 2), Some(3));
    assert_eq!(hash.opposite_vertex(1, 0, 3), Some(2));
    assert_eq!(hash.opposite_vertex(0, 1, 4), None);
    assert_eq!(hash.opposite_vertex(1, 2, 0), None);
    assert_eq!(hash.opposite_vertex(2, 5, 2), None);
    assert_eq!(hash.opposite_vertex(3, 3, 0), None);
    // Two copies of one triangle (e.g. both windings) are not each other's opposite vertices.
    let twice = antialias_construct_topology_hash(&[[0, 1, 2], [2, 1, 0]]);
    for (a, b, own) in [(0, 1, 2), (1, 2, 0), (2, 0, 1)] {
        assert_eq!(twice.opposite_vertex(a, b, own), None);
    }
}

// ---- 2. a closed mesh ----

#[test]
fn closed_octahedron_blends_only_along_its_silhouette() {
    let (verts, tri) = octahedron();
    let hash = TopologyHash::new(&tri);
    for t in &tri {
        for (own, &(i, j)) in EDGE_ENDS.iter().enumerate() {
            assert!(
                hash.opposite_vertex(t[i], t[j], t[own]).is_some(),
                "closed: every edge has two sides"
            );
        }
    }
    let size = 16;
    let mut scene = single_image(posed(&verts, 0.6, 0.35), tri.clone(), size, size, 3);
    // Flat colour per face, another for the background: interior edges are colour edges too.
    scene.color = (0..size * size)
        .flat_map(|p| {
            let t = id(&scene, p);
            [
                0.1 * t,
                1.0 - 0.07 * t,
                if t == 0.0 { 0.5 } else { 0.3 * (t % 3.0) },
            ]
        })
        .collect();
    let s = scene.shape;
    let pairs = find_edge_pairs(&scene.input(), Some(&hash)).unwrap();
    let out = antialias(&scene.input(), Some(&hash)).unwrap();

    let mut interior_pairs = 0;
    let mut next_to_background = vec![false; size * size];
    for y in 0..size {
        for x in 0..size {
            let p = y * size + x;
            for (q, ok) in [(p + 1, x + 1 < size), (p + size, y + 1 < size)] {
                if !ok || id(&scene, p) == id(&scene, q) {
                    continue;
                }
                if id(&scene, p) == 0.0 || id(&scene, q) == 0.0 {
                    next_to_background[p] = true;
                    next_to_background[q] = true;
                } else {
                    interior_pairs += 1;
                }
            }
        }
    }
    assert!(
        interior_pairs > 10,
        "the view shows interior edges ({interior_pairs} pairs)"
    );
    assert!(
        pairs.len() > 10,
        "the silhouette is blended ({} pairs)",
        pairs.len()
    );
    for pair in &pairs {
        let ids = [
            id(&scene, pair.first_pixel(s)),
            id(&scene, pair.second_pixel(s)),
        ];
        assert!(
            ids.contains(&0.0),
            "a blended pair straddles the silhouette: {pair:?}"
        );
    }
    let mut changed = 0;
    for p in 0..size * size {
        let same = (0..3).all(|ch| out[3 * p + ch] == scene.color[3 * p + ch]);
        if !same {
            changed += 1;
            assert!(
                next_to_background[p],
                "pixel {p} changed away from the silhouette"
            );
            assert!(pairs.iter().any(|q| q.target_pixel(s) == p));
        }
        if !next_to_background[p] {
            assert!(same, "pixel {p} is unchanged");
        }
    }
    println!(
        "octahedron 16x16: {} blended pairs, {changed} pixels changed, {interior_pairs} interior pairs untouched",
        pairs.len()
    );
    assert!(changed > 10);

    // The same triangles with unshared vertices: every edge is a silhouette, so interior
    // pairs blend too.
    let split_pos: Vec<f64> = tri
        .iter()
        .flat_map(|t| {
            t.iter()
                .flat_map(|&v| scene.pos[4 * v as usize..4 * v as usize + 4].to_vec())
        })
        .collect();
    let split_tri: Vec<[u32; 3]> = (0..tri.len() as u32)
        .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
        .collect();
    let split = AntialiasInput {
        pos: &split_pos,
        pos_layout: PosLayout::Range {
            vertices: 3 * tri.len(),
        },
        tri: &split_tri,
        ..scene.input()
    };
    let split_pairs = find_edge_pairs(&split, None).unwrap();
    let interior_blended = split_pairs
        .iter()
        .filter(|q| id(&scene, q.first_pixel(s)) != 0.0 && id(&scene, q.second_pixel(s)) != 0.0)
        .count();
    println!("unwelded: {interior_blended} interior pairs blended");
    assert!(interior_blended > 5);
}

// ---- 5. the blend against exact coverage ----

/// `∫_{−1/2}^{1/2} clamp(a + b·y, 0, 1) dy` exactly, and the length of `y` where the clamp
/// does not bind (its derivative in `a`). The integrand is linear between the cuts, so the
/// midpoint rule is exact on each piece.
fn clamped_strip(a: f64, b: f64) -> (f64, f64) {
    let mut cuts = vec![-0.5, 0.5];
    if b != 0.0 {
        for level in [0.0, 1.0] {
            let y = (level - a) / b;
            if y > -0.5 && y < 0.5 {
                cuts.push(y);
            }
        }
    }
    cuts.sort_by(f64::total_cmp);
    let (mut area, mut active) = (0.0, 0.0);
    for w in cuts.windows(2) {
        let v = a + b * 0.5 * (w[0] + w[1]);
        area += (w[1] - w[0]) * v.clamp(0.0, 1.0);
        if v > 0.0 && v < 1.0 {
            active += w[1] - w[0];
        }
    }
    (area, active)
}

#[test]
fn blend_factor_against_exact_box_coverage() {
    // An 8 × 8 image, one straight edge x = 3.5 + r + s·(y − 3.5) (pixels) with the
    // triangle to its left, so the pair (3, 3)–(4, 3) has its crossing at r from pixel
    // 0's centre. Colour 1 on the triangle, 0 off it: the forward's pixel 0 shows
    // B₀ = 1 − out₀ background, pixel 1 shows B₁ = out₁ triangle. Exact: A₀ = area of pixel
    // 0's box right of the line, A₁ = area of pixel 1's box left of it. Derivatives in r
    // from the backward (ε = 0, so they are the forward's own) against the exact ones.
    // The transposed scene (a near-horizontal edge, a next-row pair) must agree.
    let size = 8;
    let pixel0 = 3 * size + 3;
    let mut report = Vec::new();
    for s in [0.0, 0.25, 0.5, 0.75, 0.95, -0.6] {
        let mut worst = [0.0f64; 4]; // |A₀ − B₀|, |A₁ − B₁|, |A₀' − B₀'|, |A₁' − B₁'|
        for transposed in [false, true] {
            let pixel1 = if transposed {
                pixel0 + size
            } else {
                pixel0 + 1
            };
            for step in 0..50 {
                let r = 0.01 + 0.02 * step as f64;
                let line = |y: f64| 3.5 + r + s * (y - 3.5);
                let px = [[line(-50.0), -50.0], [line(58.0), 58.0], [-100.0, 4.0]];
                let clip = px
                    .iter()
                    .flat_map(|&[x, y]| {
                        let (x, y) = if transposed { (y, x) } else { (x, y) };
                        [
                            2.0 * x / size as f64 - 1.0,
                            2.0 * y / size as f64 - 1.0,
                            0.0,
                            1.0,
                        ]
                    })
                    .collect();
                let mut scene = single_image(clip, vec![[0, 1, 2]], size, size, 1);
                assert_eq!((id(&scene, pixel0), id(&scene, pixel1)), (1.0, 0.0));
                scene.color = scene
                    .rast
                    .chunks(4)
                    .map(|r| if r[3] > 0.0 { 1.0 } else { 0.0 })
                    .collect();
                let out = antialias(&scene.input(), None).unwrap();
                let (b0, b1) = (1.0 - out[pixel0], out[pixel1]);
                // d out / d r: both edge ends move by one pixel = 2/size in NDC.
                let slope = |pixel: usize| {
                    let mut dy = vec![0.0; size * size];
                    dy[pixel] = 1.0;
                    let g = backward_with_epsilon(&scene.input(), None, &dy, 1.0, 0.0).unwrap();
                    let axis = usize::from(transposed);
                    (g.pos[axis] + g.pos[4 + axis]) * 2.0 / size as f64
                };
                let (db0, db1) = (-slope(pixel0), slope(pixel1));
                let (a0, act0) = clamped_strip(0.5 - r, -s);
                let (a1, act1) = clamped_strip(r - 0.5, s);
                let (da0, da1) = (-act0, act1);
                // Net transfer and its derivative are exact.
                assert!(((b0 - b1) - (a0 - a1)).abs() < 1e-12, "s {s} r {r}");
                assert!(((db0 - db1) - (da0 - da1)).abs() < 1e-9, "s {s} r {r}");
                // Exact where the line stays in one box over the box's height.
                if r + s.abs() / 2.0 <= 0.5 || r - s.abs() / 2.0 >= 0.5 {
                    assert!(
                        (a0 - b0).abs() < 1e-12 && (a1 - b1).abs() < 1e-12,
                        "s {s} r {r}"
                    );
                    assert!(
                        (da0 - db0).abs() < 1e-9 && (da1 - db1).abs() < 1e-9,
                        "s {s} r {r}"
                    );
                }
                assert!((a0 - b0).abs() <= s.abs() / 8.0 + 1e-12);
                for (w, d) in worst
                    .iter_mut()
                    .zip([a0 - b0, a1 - b1, da0 - db0, da1 - db1])
                {
                    *w = w.max(d.abs());
                }
            }
        }
        report.push(format!(
            "s = {s:5.2}: max |A0-B0| {:.4}, |A1-B1| {:.4}, |A0'-B0'| {:.4}, |A1'-B1'| {:.4}",
            worst[0], worst[1], worst[2], worst[3]
        ));
    }
    println!("{}", report.join("\n"));
    // The exact areas themselves, against 400 × 400 supersampling of pixel 0's box.
    for (r, s) in [(0.2, 0.7), (0.45, 0.95), (0.05, 0.3)] {
        let n = 400;
        let inside = (0..n * n)
            .filter(|i| {
                let (x, y) = ((i % n) as f64 + 0.5, (i / n) as f64 + 0.5);
                let (x, y) = (x / n as f64 - 0.5, y / n as f64 - 0.5);
                x > r + s * y
            })
            .count();
        let sampled = inside as f64 / (n * n) as f64;
        assert!((sampled - clamped_strip(0.5 - r, -s).0).abs() < 5e-3);
    }
}
