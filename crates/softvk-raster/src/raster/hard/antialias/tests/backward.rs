//! The backward's tests: colour and position gradients against central differences, the
//! slack and the boost, layouts and rejected inputs.

use super::super::backward::backward_with_epsilon;
use super::*;
// ---- 3. colour gradient ----

#[test]
fn grad_color_matches_central_differences() {
    let mut rng = Rng(3);
    let scene = instanced_octahedra(&[(0.6, 0.35), (-0.4, 0.8)], 16, 3, &mut rng);
    let dy = rng.values(scene.color.len(), -1.0, 1.0);
    let grad = antialias_backward(&scene.input(), None, &dy, 1.0).unwrap();
    let h = 0.5; // the forward is linear in colour: any step is exact but for rounding
    let mut worst: f64 = 0.0;
    let mut color = scene.color.clone();
    for k in 0..color.len() {
        let c0 = color[k];
        color[k] = c0 + h;
        let up = loss(
            &AntialiasInput {
                color: &color,
                ..scene.input()
            },
            &dy,
        );
        color[k] = c0 - h;
        let down = loss(
            &AntialiasInput {
                color: &color,
                ..scene.input()
            },
            &dy,
        );
        color[k] = c0;
        worst = worst.max(((up - down) / (2.0 * h) - grad.color[k]).abs());
    }
    println!(
        "grad_color: max |analytic - central difference| = {worst:e} over {} components",
        color.len()
    );
    assert!(worst < 1e-12);
}

// ---- 4. position gradient ----

/// Checks `grad_pos` (exact, ε = 0; and nvdiffrast's ε) against central differences of
/// the forward for fixed `rast`, skipping components whose step changes a decision.
/// Returns (compared, skipped, worst exact error, worst relative error with nvdiffrast's ε).
fn check_pos_gradient(scene: &Scene, dy: &[f64]) -> (usize, usize, f64, f64) {
    let h = 1e-6;
    let exact = backward_with_epsilon(&scene.input(), None, dy, 1.0, 0.0).unwrap();
    let nv = antialias_backward(&scene.input(), None, dy, 1.0).unwrap();
    let base = decisions(&scene.input());
    let (mut compared, mut skipped) = (0, 0);
    let (mut worst, mut worst_rel): (f64, f64) = (0.0, 0.0);
    let mut pos = scene.pos.clone();
    for k in 0..pos.len() {
        if k % 4 == 2 {
            assert_eq!(exact.pos[k], 0.0, "z gets no gradient");
            assert_eq!(nv.pos[k], 0.0, "z gets no gradient");
        }
        let p0 = pos[k];
        pos[k] = p0 + h;
        let up_ok = decisions(&scene.input_with(&pos)) == base;
        let up = loss(&scene.input_with(&pos), dy);
        pos[k] = p0 - h;
        let down_ok = decisions(&scene.input_with(&pos)) == base;
        let down = loss(&scene.input_with(&pos), dy);
        pos[k] = p0;
        if !(up_ok && down_ok) {
            skipped += 1;
            continue;
        }
        compared += 1;
        let fd = (up - down) / (2.0 * h);
        worst = worst.max((fd - exact.pos[k]).abs() / (1.0 + fd.abs()));
        if fd.abs() > 1e-3 {
            worst_rel = worst_rel.max((nv.pos[k] - fd).abs() / fd.abs());
        }
    }
    (compared, skipped, worst, worst_rel)
}

#[test]
fn grad_pos_matches_central_differences_with_rast_fixed() {
    let mut rng = Rng(7);
    let instanced = instanced_octahedra(&[(0.6, 0.35), (-0.4, 0.8)], 16, 2, &mut rng);
    let ranged = ranged_scene(16, 2, &mut rng);
    for (name, scene) in [
        ("instanced octahedra", &instanced),
        ("range mode, two layers", &ranged),
    ] {
        let dy = rng.values(scene.color.len(), -1.0, 1.0);
        let pairs = find_edge_pairs(&scene.input(), None).unwrap();
        let grad = antialias_backward(&scene.input(), None, &dy, 1.0).unwrap();
        let moving = grad.pos.iter().filter(|g| **g != 0.0).count();
        let (compared, skipped, worst, worst_rel) = check_pos_gradient(scene, &dy);
        println!(
            "{name}: {} pairs, {moving}/{} components with a gradient; {compared} compared, \
             {skipped} skipped (a decision flips); exact: max |err|/(1+|fd|) = {worst:e}; \
             nvdiffrast eps: max rel err = {worst_rel:e}",
            pairs.len(),
            grad.pos.len()
        );
        assert!(
            moving >= scene.pos.len() / 2,
            "most components move the silhouette"
        );
        assert!(compared >= 4 * skipped && compared > 0);
        assert!(worst < 1e-7, "exact derivative");
        assert!(worst_rel < 2e-3, "nvdiffrast's 1e-3 guard on Δy");
    }
    // Both depth orders occur in the layered image.
    let layered: Vec<_> = find_edge_pairs(&ranged.input(), None)
        .unwrap()
        .into_iter()
        .filter(|p| p.batch == 1 && p.triangle == 9)
        .collect();
    assert!(layered.iter().any(|p| p.from_second) && layered.iter().any(|p| !p.from_second));
}

#[test]
fn a_crossing_in_the_slack_saturates_and_passes_no_position_gradient() {
    // A triangle right of a vertical edge at pixel x = 1.53, so pixel 1's centre (1.5) is
    // 0.03 px outside it; the rast marks pixel 1 covered anyway, as a rasterizer that snaps
    // vertices may. The crossing lies within the 1/16 slack behind pixel 1's centre: r
    // clamps to 0, α = −1/2 (pixel 1 becomes the mean of the two) and no gradient reaches
    // the positions.
    let e = 2.0 * 1.53 / 4.0 - 1.0;
    let clip = [[10.0, -10.0], [e, 10.0], [e, -10.0]]
        .iter()
        .flat_map(|&[x, y]| [x, y, 0.0, 1.0])
        .collect();
    let mut scene = single_image(clip, vec![[0, 1, 2]], 4, 1, 1);
    assert_eq!(
        (0..4).map(|p| id(&scene, p)).collect::<Vec<_>>(),
        [0.0, 0.0, 1.0, 1.0]
    );
    scene.rast[4 + 3] = 1.0;
    scene.color = vec![0.0, 1.0, 5.0, 6.0];
    let pairs = find_edge_pairs(&scene.input(), None).unwrap();
    assert_eq!(pairs.len(), 1);
    assert_eq!((pairs[0].x, pairs[0].from_second), (0, true));
    assert_eq!(pairs[0].alpha, -0.5);
    let out = antialias(&scene.input(), None).unwrap();
    assert_eq!(out, [0.0, 0.5, 5.0, 6.0]);
    let grad = antialias_backward(&scene.input(), None, &[0.0, 1.0, 0.0, 0.0], 1.0).unwrap();
    assert!(grad.pos.iter().all(|&g| g == 0.0));
    assert_eq!(grad.color, [0.5, 0.5, 0.0, 0.0]);
    // Past the slack (0.1 px outside) the pair is not blended at all.
    scene.pos[4] = 2.0 * 1.6 / 4.0 - 1.0;
    scene.pos[8] = scene.pos[4];
    assert!(find_edge_pairs(&scene.input(), None).unwrap().is_empty());
}

#[test]
fn pos_gradient_boost_scales_only_the_position_gradient() {
    let mut rng = Rng(11);
    let scene = instanced_octahedra(&[(0.2, 0.5)], 12, 2, &mut rng);
    let dy = rng.values(scene.color.len(), -1.0, 1.0);
    let one = antialias_backward(&scene.input(), None, &dy, 1.0).unwrap();
    let boosted = antialias_backward(&scene.input(), None, &dy, 3.0).unwrap();
    assert_eq!(one.color, boosted.color);
    assert!(one.pos.iter().any(|&g| g != 0.0));
    for (a, b) in one.pos.iter().zip(&boosted.pos) {
        assert_eq!(3.0 * a, *b);
    }
}

#[test]
fn instanced_layout_equals_range_layout_with_offset_copies() {
    // [B, V, 4] instanced equals range mode over the concatenated vertices, each item
    // drawing its own copy of the triangles (ids shifted by the copy's offset).
    let mut rng = Rng(5);
    let inst = instanced_octahedra(&[(0.6, 0.35), (-0.4, 0.8)], 16, 2, &mut rng);
    let t = inst.tri.len();
    let tri2: Vec<[u32; 3]> = inst
        .tri
        .iter()
        .copied()
        .chain(inst.tri.iter().map(|v| v.map(|i| i + 6)))
        .collect();
    let mut rast2 = inst.rast.clone();
    for (p, px) in rast2.chunks_mut(4).enumerate() {
        if p >= 256 && px[3] != 0.0 {
            px[3] += t as f64;
        }
    }
    let ranged = AntialiasInput {
        rast: &rast2,
        pos_layout: PosLayout::Range { vertices: 12 },
        tri: &tri2,
        ..inst.input()
    };
    let dy = rng.values(inst.color.len(), -1.0, 1.0);
    assert_eq!(
        antialias(&inst.input(), None).unwrap(),
        antialias(&ranged, None).unwrap()
    );
    assert_eq!(
        antialias_backward(&inst.input(), None, &dy, 1.0).unwrap(),
        antialias_backward(&ranged, None, &dy, 1.0).unwrap()
    );
}

#[test]
fn inconsistent_inputs_are_rejected() {
    let mut rng = Rng(1);
    let scene = instanced_octahedra(&[(0.2, 0.5)], 8, 1, &mut rng);
    let short = &scene.color[1..];
    assert!(
        antialias(
            &AntialiasInput {
                color: short,
                ..scene.input()
            },
            None
        )
        .is_err()
    );
    assert!(
        antialias(
            &AntialiasInput {
                rast: &scene.rast[4..],
                ..scene.input()
            },
            None
        )
        .is_err()
    );
    let layout = PosLayout::Instanced { vertices: 5 };
    assert!(
        antialias(
            &AntialiasInput {
                pos_layout: layout,
                ..scene.input()
            },
            None
        )
        .is_err()
    );
    assert!(
        antialias(
            &AntialiasInput {
                tri: &[[0, 1, 6]],
                ..scene.input()
            },
            None
        )
        .is_err()
    );
    let other = TopologyHash::new(&[[0, 1, 2]]);
    assert!(antialias(&scene.input(), Some(&other)).is_err());
    assert!(antialias_backward(&scene.input(), None, &[0.0; 3], 1.0).is_err());
}
