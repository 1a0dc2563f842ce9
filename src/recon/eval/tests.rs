//! Tests of the scoring: masks, retrieval and the mean shape, the voxelizers on closed, self-
//! overlapping and open meshes, and the bootstrap's intervals.

use super::bootstrap::percentile;
use super::*;

#[test]
fn mask_iou_counts_pixels_at_half_alpha_and_above() {
    let a = Mask::from_alpha(&[0, 127, 128, 255, 200, 0, 0]);
    let b = Mask::from_alpha(&[255, 255, 128, 0, 200, 0, 0]);
    // a = {2, 3, 4}, b = {0, 1, 2, 4}: ∩ = {2, 4}, ∪ = {0, 1, 2, 3, 4}.
    assert_eq!(a.iou(&b), 2.0 / 5.0);
    assert_eq!(
        Mask::from_alpha(&[0; 70]).iou(&Mask::from_alpha(&[0; 70])),
        1.0
    );
}

#[test]
fn retrieval_picks_the_best_match_and_the_first_of_equals() {
    let q = Mask::from_alpha(&[255, 255, 0, 0]);
    let c = [
        Mask::from_alpha(&[0, 0, 255, 255]),
        Mask::from_alpha(&[255, 0, 0, 0]),
        Mask::from_alpha(&[0, 255, 0, 0]),
    ];
    assert_eq!(retrieve(&q, &c), Some(1));
    assert_eq!(retrieve(&q, &[]), None);
}

#[test]
fn mean_shape_keeps_cells_of_at_least_half_the_objects() {
    let (a, b, c) = (
        [true, true, false, false],
        [true, false, true, false],
        [true, false, false, false],
    );
    assert_eq!(
        mean_shape(&[&a, &b, &c]).unwrap(),
        vec![true, false, false, false]
    );
    assert_eq!(
        mean_shape(&[&a, &b]).unwrap(),
        vec![true, true, true, false]
    );
    assert!(matches!(mean_shape(&[]), Err(Error::Input(_))));
    assert_eq!(voxel_iou(&a, &b).unwrap(), 1.0 / 3.0);
    assert!(matches!(voxel_iou(&a, &[true]), Err(Error::Input(_))));
}

/// `mesh` moved by `d`.
fn moved(mesh: &crate::mesh::Mesh, d: [f32; 3]) -> Vec<[f32; 3]> {
    mesh.positions
        .iter()
        .map(|p| [p[0] + d[0], p[1] + d[1], p[2] + d[2]])
        .collect()
}

#[test]
fn winding_and_parity_agree_on_closed_meshes_that_do_not_overlap_themselves() {
    use crate::mesh::Mesh;
    let sphere = Mesh::icosphere(3);
    let sphere: Vec<[f32; 3]> = sphere
        .positions
        .iter()
        .map(|p| [0.41 * p[0] + 0.02, 0.33 * p[1] - 0.03, 0.37 * p[2] + 0.01])
        .collect();
    let template = crate::recon::train::template();
    let bumpy: Vec<[f32; 3]> = template
        .positions
        .iter()
        .map(|p| {
            let r = 0.3 + 0.08 * (3.0 * p[0]).sin() * (2.0 * p[1]).cos();
            p.map(|c| r * c)
        })
        .collect();
    let cuboid = Mesh::cuboid([0.31, 0.22, 0.13]);
    for (positions, faces) in [
        (&sphere, &Mesh::icosphere(3).faces),
        (&bumpy, &template.faces),
        (&cuboid.positions, &cuboid.faces),
    ] {
        let parity = Voxelizer::Parity.voxelize(positions, faces).unwrap();
        let winding = Voxelizer::Winding.voxelize(positions, faces).unwrap();
        assert!(parity.iter().filter(|&&x| x).count() > 100);
        assert_eq!(parity, winding);
    }
}

#[test]
fn winding_keeps_what_a_self_overlap_doubles_where_parity_empties_it() {
    use crate::mesh::Mesh;
    // Two closed boxes in one mesh, overlapping in x ∈ [−0.12, 0.12].
    let cuboid = Mesh::cuboid([0.27, 0.2, 0.18]);
    let (a, b) = (
        moved(&cuboid, [-0.15, 0.0, 0.0]),
        moved(&cuboid, [0.15, 0.0, 0.0]),
    );
    let positions: Vec<[f32; 3]> = a.iter().chain(&b).copied().collect();
    let n = a.len() as u32;
    let faces: Vec<[u32; 3]> = cuboid
        .faces
        .iter()
        .copied()
        .chain(cuboid.faces.iter().map(|f| f.map(|i| i + n)))
        .collect();
    let one = |p: &[[f32; 3]]| Voxelizer::Parity.voxelize(p, &cuboid.faces).unwrap();
    let (a, b) = (one(&a), one(&b));
    let both = a.iter().zip(&b).filter(|(x, y)| **x && **y).count();
    assert!(both > 100, "the boxes overlap in {both} voxels");
    let parity = Voxelizer::Parity.voxelize(&positions, &faces).unwrap();
    let winding = Voxelizer::Winding.voxelize(&positions, &faces).unwrap();
    let xor: Vec<bool> = a.iter().zip(&b).map(|(x, y)| x ^ y).collect();
    let or: Vec<bool> = a.iter().zip(&b).map(|(x, y)| x | y).collect();
    assert_eq!(parity, xor, "parity empties the overlap");
    assert_eq!(winding, or, "the winding number keeps it");
}

#[test]
fn an_inside_out_mesh_is_inside_by_winding_and_an_open_one_is_refused() {
    use crate::mesh::Mesh;
    let sphere = Mesh::icosphere(2);
    let positions: Vec<[f32; 3]> = sphere
        .positions
        .iter()
        .map(|p| p.map(|c| 0.4 * c))
        .collect();
    let reversed: Vec<[u32; 3]> = sphere.faces.iter().map(|f| [f[0], f[2], f[1]]).collect();
    let outward = Voxelizer::Winding
        .voxelize(&positions, &sphere.faces)
        .unwrap();
    let inward = Voxelizer::Winding.voxelize(&positions, &reversed).unwrap();
    assert!(outward.iter().filter(|&&x| x).count() > 1000);
    assert_eq!(inward, outward);
    // A hole, or one face turned against its neighbours: no winding number to count.
    let open = &sphere.faces[1..];
    let mut flipped = sphere.faces.clone();
    flipped[3].swap(1, 2);
    for faces in [open, &flipped[..]] {
        let err = Voxelizer::Winding.voxelize(&positions, faces).unwrap_err();
        assert!(
            matches!(&err, Error::Input(m) if m.contains("closed, consistently oriented")),
            "{err}"
        );
    }
}

/// Columns of `n` units: `base[i] + shift + noise[i]`, the noise ±`spread` alternating.
fn shifted(base: &[f64], shift: f64, spread: f64) -> Vec<f64> {
    base.iter()
        .enumerate()
        .map(|(i, b)| b + shift + if i % 2 == 0 { spread } else { -spread })
        .collect()
}

/// `n` values spread over [0, 1) (a fixed pseudo-random draw).
fn spread(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = crate::rng::SplitMix64(seed);
    (0..n).map(|_| rng.unit()).collect()
}

#[test]
fn identical_columns_differ_by_exactly_zero() {
    let a = spread(9, 1);
    let i = paired_bootstrap(&[(&a, &a)], 1000, 7).unwrap();
    assert_eq!((i.mean, i.lo, i.hi), (0.0, 0.0, 0.0));
}

#[test]
fn a_known_shift_is_inside_its_interval_and_more_objects_narrow_it() {
    let width = |n: usize| {
        let b = spread(n, 3);
        let a = shifted(&b, 0.1, 0.1);
        let i = paired_bootstrap(&[(&a, &b)], RESAMPLES, BOOTSTRAP_SEED).unwrap();
        assert!((i.mean - 0.1).abs() < 1e-12, "{i:?}");
        assert!(i.lo < 0.1 && 0.1 < i.hi, "{i:?}");
        assert!(
            i.lo > 0.0,
            "{n} objects: a shift as large as the noise is clear: {i:?}"
        );
        i.hi - i.lo
    };
    let (few, many) = (width(16), width(256));
    // The width goes as 1/√n: 4 times narrower for 16 times the objects.
    assert!(few > 3.0 * many && few < 5.0 * many, "{few} {many}");
}

#[test]
fn pairing_cancels_what_both_columns_share() {
    // Objects of very different difficulty (IoUs over [0, 1)), the network ahead of the
    // baseline by 0.1 on every one.
    let b = spread(24, 5);
    let a: Vec<f64> = b.iter().map(|x| x + 0.1).collect();
    let paired = paired_bootstrap(&[(&a, &b)], RESAMPLES, BOOTSTRAP_SEED).unwrap();
    assert!((paired.lo - 0.1).abs() < 1e-12 && (paired.hi - 0.1).abs() < 1e-12);
    // Resampling the two columns independently sees the spread of difficulty instead.
    let mut rng = crate::rng::SplitMix64(BOOTSTRAP_SEED);
    let mut draw = |v: &[f64]| {
        (0..v.len())
            .map(|_| v[(rng.next_u64() % v.len() as u64) as usize])
            .sum::<f64>()
            / v.len() as f64
    };
    let mut unpaired: Vec<f64> = (0..RESAMPLES).map(|_| draw(&a) - draw(&b)).collect();
    unpaired.sort_by(f64::total_cmp);
    let width = percentile(&unpaired, 0.975) - percentile(&unpaired, 0.025);
    assert!(width > 0.2, "unpaired: {width}");
}

#[test]
fn the_overall_interval_is_of_the_mean_of_class_means_resampled_within_classes() {
    // Class one (2 objects) ahead by 1, class two (8 objects) by 0: the mean of the class
    // means is 0.5 whatever the resample; pooling the objects would say 0.2 and spread.
    let (a1, b1) = ([1.0, 1.0], [0.0, 0.0]);
    let (a2, b2) = (spread(8, 9), spread(8, 9));
    let i = paired_bootstrap(&[(&a1, &b1), (&a2, &b2)], 1000, 0).unwrap();
    assert_eq!((i.mean, i.lo, i.hi), (0.5, 0.5, 0.5));
    assert!(matches!(
        paired_bootstrap(&[(&a1, &b2)], 10, 0),
        Err(Error::Input(_))
    ));
}

#[test]
fn later_networks_are_compared_with_the_first_on_the_same_objects() {
    // Network 1 is network 0 plus 0.05 on every object (objects that vary a lot), network 2
    // is network 0 itself: exact differences, whatever the resample, in every class and
    // over the classes; and they appear in the text and the CSV.
    let row = |class: &str, seed: u64| {
        let n0 = spread(12, seed);
        let n1: Vec<f64> = n0.iter().map(|x| x + 0.05).collect();
        let base = spread(12, seed + 1);
        ScoreRow {
            class: class.into(),
            inputs: 12,
            networks: vec![n0.clone(), n1, n0],
            baselines: [base.clone(), base.clone(), base.clone(), base],
        }
    };
    let rows = [row("a", 3), row("b", 5)];
    let cmp = compare(&rows).unwrap();
    assert_eq!(cmp.versus_first.len(), 3, "two classes and the mean");
    for per in &cmp.versus_first {
        assert_eq!(per.len(), 2);
        for (i, want) in per.iter().zip([0.05, 0.0]) {
            for x in [i.mean, i.lo, i.hi] {
                assert!((x - want).abs() < 1e-12, "{i:?} vs {want}");
            }
        }
    }
    let names: Vec<String> = ["mesh", "field", "again"].map(String::from).to_vec();
    let text = format_comparison(&names, &rows, &cmp);
    assert!(text.contains("network − mesh"), "{text}");
    let csv = table_csv(&names, &rows, &cmp);
    assert!(csv.contains("\"mean\",\"field\",\"mesh\",0.05"), "{csv}");
    let one = compare(&rows.map(|mut r| {
        r.networks.truncate(1);
        r
    }))
    .unwrap();
    assert!(one.versus_first.iter().all(Vec::is_empty));
}
