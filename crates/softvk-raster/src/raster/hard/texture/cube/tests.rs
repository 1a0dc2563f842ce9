//! Tests of the cube-map twin: the face table, the per-face mip stack, the level and its
//! gradient, corner taps, seams, the backward against central differences, and what a lookup
//! refuses.

use super::super::tests::{near_integer, stream};
use super::super::{Boundary, Filter, LevelInput, Mode, sample};
use super::level::cube_mip_levels;
use super::*;

/// A cube map of `cubes` cubes with `size × size` faces of `channels` random values in
/// [0, 1), and its mip stack.
fn random_cube(seed: u64, cubes: usize, size: usize, channels: usize) -> MipStack {
    let mut rnd = stream(seed);
    let texels = (0..cubes * 6 * size * size * channels)
        .map(|_| rnd())
        .collect();
    MipStack::cube(cubes, size, channels, texels)
        .unwrap()
        .build(None)
        .unwrap()
}

/// One face of cube 0 of `cube` as a 2D texture of its own, with its own mip stack.
fn face_alone(cube: &MipStack, face: usize) -> MipStack {
    let (n, c) = (cube.levels[0].width, cube.channels);
    let o = face * n * n * c;
    MipStack::base(1, n, n, c, cube.levels[0].texels[o..o + n * n * c].to_vec())
        .unwrap()
        .build(None)
        .unwrap()
}

fn bias(bias: f64) -> CubeLevelInput {
    CubeLevelInput {
        uv_da: None,
        bias: Some(bias),
    }
}

#[test]
fn cube_faces_follow_the_opengl_table() {
    assert_eq!(cube_face([1.0, 0.0, 0.0]), Some((0, 0.5, 0.5)));
    assert_eq!(cube_face([2.0, 1.0, -1.0]), Some((0, 0.75, 0.25)));
    assert_eq!(cube_face([-2.0, 1.0, -1.0]), Some((1, 0.25, 0.25)));
    assert_eq!(cube_face([0.5, 2.0, 1.0]), Some((2, 0.625, 0.75)));
    assert_eq!(cube_face([0.5, -2.0, 1.0]), Some((3, 0.625, 0.25)));
    assert_eq!(cube_face([0.5, 1.0, 2.0]), Some((4, 0.625, 0.25)));
    assert_eq!(cube_face([0.5, 1.0, -2.0]), Some((5, 0.375, 0.25)));
    assert_eq!(cube_face([0.0; 3]), None);
    assert_eq!(cube_face([f64::NAN, 1.0, 0.0]), None);
    // Ties go to x, then y; a zero major component's sign is positive.
    assert_eq!(cube_face([1.0, 1.0, 1.0]).unwrap().0, 0);
    assert_eq!(cube_face([-1.0, 0.5, 1.0]).unwrap().0, 1);
    assert_eq!(cube_face([0.5, -1.0, 1.0]).unwrap().0, 3);
    // cube_direction inverts it on every face.
    for face in 0..6 {
        let (f, s, t) = cube_face(cube_direction(face, 0.3, 0.8)).unwrap();
        assert_eq!(f, face);
        assert!(
            (s - 0.3).abs() < 1e-15 && (t - 0.8).abs() < 1e-15,
            "{face}: {s} {t}"
        );
    }
}

/// `texture_construct_mip(cube_mode=True)`: each face of each cube halved on its own, and
/// the pyramid's backward carries a level's gradient into its own face's texels only.
#[test]
fn the_cube_mip_stack_halves_each_face_apart() {
    let (n, c) = (4usize, 2usize);
    let texels: Vec<f64> = (0..2 * 6 * n * n * c)
        .map(|i| f64::from(i as u32))
        .collect();
    let two = MipStack::cube(2, n, c, texels.clone())
        .unwrap()
        .build(None)
        .unwrap();
    assert_eq!(two.max_level(), 2);
    for item in 0..12 {
        let o = item * n * n * c;
        let alone = MipStack::base(1, n, n, c, texels[o..o + n * n * c].to_vec())
            .unwrap()
            .build(None)
            .unwrap();
        for level in 1..=2 {
            let m = n >> level;
            let p = item * m * m * c;
            assert_eq!(
                two.levels[level].texels[p..p + m * m * c],
                alone.levels[level].texels[..],
                "item {item} level {level}"
            );
        }
        // The last level is each face's mean, channel by channel.
        for k in 0..c {
            let mean = (0..n * n).map(|i| texels[o + i * c + k]).sum::<f64>() / 16.0;
            assert_eq!(two.levels[2].texels[item * c + k], mean);
        }
    }
    // A unit gradient on the 1 × 1 level of cube 1's face −y, channel 1, goes to that
    // face's sixteen texels alone, a sixteenth each.
    let mut grads = two.zero_grads();
    let item = 6 + 3;
    grads[2][item * c + 1] = 1.0;
    let base = two.pyramid_backward(grads);
    for (i, g) in base.iter().enumerate() {
        let inside = i / (n * n * c) == item && i % c == 1;
        assert_eq!(*g, if inside { 1.0 / 16.0 } else { 0.0 }, "texel value {i}");
    }
    // Faces whose size cannot halve down, and a wrong count of values, are errors.
    let odd = MipStack::cube(1, 6, 1, vec![0.0; 6 * 36]).unwrap();
    assert!(odd.clone().build(Some(1)).is_ok());
    assert!(odd.build(None).is_err());
    assert!(MipStack::cube(1, 4, 1, vec![0.0; 16]).is_err());
    assert!(MipStack::cube(0, 4, 1, vec![]).is_err());
}

/// λ by hand: a face's coordinates move by `±1/(2|m|)` with a minor component and by
/// `−(s − ½)/m` with the major one `m`, in texels of the base face.
#[test]
fn the_cube_level_is_the_footprint_on_the_face_in_its_texels() {
    let at = |dir: [f64; 3], uv_da: [f64; 6], bias: Option<f64>| {
        let input = CubeLevelInput {
            uv_da: Some(uv_da),
            bias,
        };
        cube_level_of_detail(dir, input, 16)
    };
    // Straight at +z's centre, the direction moving 0.5 along x a pixel across and 0.125
    // along y a pixel down: s moves ¼ (4 texels), t ⅛ · ½ (1 texel): λ = log2 4 = 2.
    let da = [0.5, 0.0, 0.0, 0.125, 0.0, 0.0];
    assert_eq!(at([0.0, 0.0, 1.0], da, None), 2.0);
    // Three times as long a direction, the same derivatives: a third of the footprint.
    let l = at([0.0, 0.0, 3.0], da, None);
    assert!((l - (4.0f64 / 3.0).log2()).abs() < 1e-14, "{l}");
    // X and Y swapped (the layout interleaves them per component): the same level.
    assert_eq!(
        at([0.0, 0.0, 1.0], [0.0, 0.5, 0.125, 0.0, 0.0, 0.0], None),
        2.0
    );
    // Along the major axis at the centre, s and t stand still: λ = −∞ (level 0).
    assert_eq!(
        at([0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0, 1.0, 1.0], None),
        f64::NEG_INFINITY
    );
    // Off the centre the major component moves s: at (0.5, 0, 1), ds/dz = −¼, 4 texels.
    assert_eq!(
        at([0.5, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0, 1.0, 0.0], None),
        2.0
    );
    // On −x, s = z/(2|x|) + ½: dz/dX = 1 at x = −2 moves s by ¼; the bias adds.
    assert_eq!(
        at([-2.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 1.0, 0.0], Some(0.5)),
        2.5
    );
    // The face derivatives themselves: ds/dX = ½ · 1 − ¼ · 1, dt/dY = −½ · 2.
    assert_eq!(
        cube_face_derivatives([0.5, 0.0, 1.0], [1.0, 0.0, 0.0, 2.0, 1.0, 0.0]),
        [0.25, 0.0, 0.0, -1.0]
    );
    // No face, no footprint.
    assert_eq!(cube_face_derivatives([0.0; 3], [1.0; 6]), [0.0; 4]);
}

/// The level's gradients are zero where the footprint on the face is isotropic (0/0), and
/// for a direction with no face, as nvdiffrast's.
#[test]
fn an_isotropic_cube_footprint_gives_the_level_no_gradient() {
    let zero = CubeLevelGrad::default();
    let round = [0.5, 0.0, 0.0, 0.5, 0.0, 0.0];
    assert_eq!(cube_level_gradient([0.0, 0.0, 1.0], round, 16), zero);
    assert_eq!(cube_level_gradient([0.0; 3], [0.5; 6], 16), zero);
    let long = [0.5, 0.0, 0.0, 0.25, 0.0, 0.0];
    let g = cube_level_gradient([0.2, 0.1, 1.0], long, 16);
    assert!(g.uv_da.iter().any(|g| *g != 0.0) && g.dir.iter().any(|g| *g != 0.0));
}

/// In a face's interior, where no tap leaves the face, every mode reads the levels the
/// level picks as 2D sampling of that face alone does (an oracle that knows nothing of
/// cubes), by the bias and by `uv_da` alike.
#[test]
fn cube_mipmap_modes_read_the_levels_the_level_picks() {
    let cube = random_cube(5, 1, 8, 3);
    // s = 0.4, t = 0.6 on +y: inside the face's taps down to level 2 (2 × 2).
    let (face, st) = (2, [0.4, 0.6]);
    let dir = cube_direction(face, st[0], st[1]).map(|x| 1.7 * x);
    let alone = face_alone(&cube, face);
    let flat = |filter: Filter, level: LevelInput| {
        let mode = Mode {
            filter,
            boundary: Boundary::Clamp,
        };
        sample(&alone, 0, st, level, mode)
    };
    let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(a, b)| (a - b).abs() < 1e-12);
    let da = [1.24, -0.48, 0.2, 1.6, 0.88, -0.28];
    for filter in [Filter::LinearMipmapNearest, Filter::LinearMipmapLinear] {
        for b in [-3.0, 0.0, 0.4, 1.0, 1.5, 1.99] {
            let got = sample_cube(&cube, 0, dir, bias(b), filter).unwrap();
            let want = flat(
                filter,
                LevelInput {
                    uv_da: None,
                    bias: Some(b),
                },
            );
            assert!(close(&got, &want), "{filter:?} bias {b}: {got:?} {want:?}");
        }
        // By uv_da: the face derivatives as the 2D uv_da give the same λ and sample.
        let level = CubeLevelInput {
            uv_da: Some(da),
            bias: Some(-0.3),
        };
        let lambda = cube_level_of_detail(dir, level, 8);
        assert!(lambda > 0.5 && lambda < 1.9, "{lambda}");
        let flat_level = LevelInput {
            uv_da: Some(cube_face_derivatives(dir, da)),
            bias: Some(-0.3),
        };
        assert_eq!(super::super::level_of_detail(flat_level, 8, 8), lambda);
        let got = sample_cube(&cube, 0, dir, level, filter).unwrap();
        assert!(close(&got, &flat(filter, flat_level)), "{filter:?} uv_da");
    }
    // Linear is level 0; a NaN level is level 0; past the last level is the last level.
    let linear = sample_cube(&cube, 0, dir, bias(2.0), Filter::Linear).unwrap();
    assert!(close(&linear, &flat(Filter::Linear, LevelInput::default())));
    let nan = sample_cube(&cube, 0, dir, bias(f64::NAN), Filter::LinearMipmapLinear);
    assert_eq!(nan.unwrap(), linear);
    let past = sample_cube(&cube, 0, dir, bias(7.0), Filter::LinearMipmapLinear);
    let last = sample_cube(&cube, 0, dir, bias(3.0), Filter::LinearMipmapNearest);
    assert_eq!(past.unwrap(), last.unwrap());
}

/// Near +z's corner with +y and −x (n = 4, s = 0.05, t = 0.1), the tap up and left is
/// beyond the corner: it reads the mean of the other three, +y's texel (0, 3) above,
/// −x's (3, 0) to the left and +z's own (0, 0), and its weight goes a third to each.
#[test]
fn a_tap_beyond_a_corner_reads_the_mean_of_the_other_three() {
    let (n, c) = (4usize, 2usize);
    let cube = random_cube(9, 1, n, c);
    let texel = |face: usize, x: usize, y: usize| -> Vec<f64> {
        let o = ((face * n + y) * n + x) * c;
        cube.levels[0].texels[o..o + c].to_vec()
    };
    let dir = cube_direction(4, 0.05, 0.1).map(|x| 0.6 * x);
    // u = 0.2 − 0.5 and v = 0.4 − 0.5: fractions 0.7 and 0.9 from the taps at −1.
    let (fs, ft) = (0.7, 0.9);
    let (a10, a01, a11) = (texel(2, 0, 3), texel(1, 3, 0), texel(4, 0, 0));
    let got = sample_cube(&cube, 0, dir, CubeLevelInput::default(), Filter::Linear).unwrap();
    for k in 0..c {
        let a00 = (a10[k] + a01[k] + a11[k]) / 3.0;
        let top = a00 + fs * (a10[k] - a00);
        let bottom = a01[k] + fs * (a11[k] - a01[k]);
        let want = top + ft * (bottom - top);
        assert!(
            (got[k] - want).abs() < 1e-14,
            "channel {k}: {} {want}",
            got[k]
        );
    }
    let mut tex_grad = cube.zero_grads();
    let dy = [1.0, 0.0];
    let level = CubeLevelInput::default();
    sample_cube_backward(&cube, 0, dir, level, Filter::Linear, &dy, &mut tex_grad).unwrap();
    let w00 = (1.0 - fs) * (1.0 - ft);
    let expect = [
        ((2, 0, 3), fs * (1.0 - ft) + w00 / 3.0),
        ((1, 3, 0), (1.0 - fs) * ft + w00 / 3.0),
        ((4, 0, 0), fs * ft + w00 / 3.0),
    ];
    let mut total = 0.0;
    for (i, g) in tex_grad[0].iter().enumerate() {
        let (face, y, x, k) = (i / (n * n * c), i / (n * c) % n, i / c % n, i % c);
        let want = expect
            .iter()
            .find(|(at, _)| *at == (face, x, y) && k == 0)
            .map_or(0.0, |(_, w)| *w);
        assert!(
            (g - want).abs() < 1e-14,
            "face {face} ({x}, {y}) channel {k}: {g}"
        );
        total += g;
    }
    assert!((total - 1.0).abs() < 1e-14);
}

/// A direction sweeping across each of the cube's twelve edges (from both faces, at the
/// edge's middle and near both its corners) gives a continuous sample on every level and
/// between levels: no step between neighbouring directions larger than the level's own
/// slope allows, where sampling each face on its own (clamped at its edge, on the same
/// level) jumps.
#[test]
fn a_cube_map_has_no_seam_across_any_edge_on_any_level() {
    let (n, c) = (8usize, 2usize);
    let cube = random_cube(3, 1, n, c);
    let faces: Vec<MipStack> = (0..6).map(|f| face_alone(&cube, f)).collect();
    let steps = 400;
    let settings = [
        (Filter::Linear, 0.0),
        (Filter::LinearMipmapNearest, 1.0),
        (Filter::LinearMipmapNearest, 2.0),
        (Filter::LinearMipmapNearest, 3.0),
        (Filter::LinearMipmapLinear, 0.5),
        (Filter::LinearMipmapLinear, 1.5),
        (Filter::LinearMipmapLinear, 2.5),
    ];
    for (filter, b) in settings {
        // One step moves the lookup by at most 0.4 / steps of a face, s and t together by
        // twice that past an edge near a corner, and texels differ by less than 1.
        let finest = (n >> b as usize) as f64;
        let bound = 2.0 * 0.4 * finest / steps as f64;
        let (mut crossings, mut seams, mut steepest) = (0, 0, 0.0f64);
        for face in 0..6 {
            for across in [0, 1] {
                for sign in [1.0, -1.0] {
                    for along in [0.3, 0.03, 0.97] {
                        // From 0.8 to 1.2 (or 0.2 to −0.2) across the edge, continued on
                        // the face's plane.
                        let at = |k: usize| {
                            let x = 0.4 * (k as f64 / steps as f64) - 0.2;
                            let out = 0.5 + sign * (0.5 + x);
                            let (s, t) = if across == 0 {
                                (out, along)
                            } else {
                                (along, out)
                            };
                            cube_direction(face, s, t)
                        };
                        let per_face = |dir: [f64; 3]| {
                            let (f, s, t) = cube_face(dir).unwrap();
                            let mode = Mode {
                                filter,
                                boundary: Boundary::Clamp,
                            };
                            let level = LevelInput {
                                uv_da: None,
                                bias: Some(b),
                            };
                            sample(&faces[f], 0, [s, t], level, mode)
                        };
                        let (mut worst, mut worst_face) = (0.0f64, 0.0f64);
                        for k in 0..steps {
                            let (da, db) = (at(k), at(k + 1));
                            let va = sample_cube(&cube, 0, da, bias(b), filter).unwrap();
                            let vb = sample_cube(&cube, 0, db, bias(b), filter).unwrap();
                            let (pa, pb) = (per_face(da), per_face(db));
                            for k in 0..c {
                                worst = worst.max((va[k] - vb[k]).abs());
                                worst_face = worst_face.max((pa[k] - pb[k]).abs());
                            }
                        }
                        assert!(
                            worst <= bound,
                            "{filter:?} bias {b} face {face} across {across} sign \
                             {sign} along {along}: step {worst} > {bound}"
                        );
                        crossings += 1;
                        steepest = steepest.max(worst);
                        // Twice the steepest step a continuous sample can take: a jump.
                        if worst_face > 2.0 * bound {
                            seams += 1;
                        }
                    }
                }
            }
        }
        eprintln!(
            "{filter:?} bias {b}: {seams} of {crossings} crossings seams per face; the \
             cube's steepest step {steepest} of {bound}"
        );
        assert!(
            seams * 10 >= crossings * 9,
            "{filter:?} bias {b}: per-face sampling shows only {seams} of {crossings} \
             crossings as seams"
        );
    }
}

/// Every gradient of one pixel (to the base texels through the pyramid, the direction,
/// `uv_da` and the bias) against central differences of the forward, per component, in
/// every filter mode, at directions in face interiors, near edges and near corners (on
/// either side), away from the kinks (counted: the draws skipped), each error within a
/// measured floor.
#[test]
fn the_cube_backward_matches_central_differences_at_interiors_edges_and_corners() {
    let mut rnd = stream(11);
    let (n, c) = (8usize, 2usize);
    let base: Vec<f64> = (0..6 * n * n * c).map(|_| rnd()).collect();
    let stack_of = |texels: Vec<f64>, filter: Filter| {
        let s = MipStack::cube(1, n, c, texels).unwrap();
        if filter.uses_mips() {
            s.build(None).unwrap()
        } else {
            s
        }
    };
    let eps = 1e-6;
    // The floor measured at eps = 1e-6: the worst error of any component is about 1e-10
    // (rounding, ~1e-16 / eps), so 1e-8 leaves a hundredfold; a wrong term in a
    // derivative errs by the order of the gradient itself (0.01 to 10).
    let floor = 1e-8;
    let mut worst = [0.0f64; 4];
    let (mut checked, mut skipped, mut edges, mut corners) = (0, 0, 0, 0);
    for filter in [
        Filter::Nearest,
        Filter::Linear,
        Filter::LinearMipmapNearest,
        Filter::LinearMipmapLinear,
    ] {
        let stack = stack_of(base.clone(), filter);
        for draw in 0..36 {
            // Within [−0.03, 0.06] of an edge, on either side of it.
            let near = |r: f64| {
                if r < 0.5 {
                    r * 0.18 - 0.03
                } else {
                    1.03 - (r - 0.5) * 0.18
                }
            };
            let face = ((rnd() * 6.0) as usize).min(5);
            let free = 0.1 + 0.8 * rnd();
            let (s, t) = match draw % 3 {
                0 => (free, 0.1 + 0.8 * rnd()),
                1 if rnd() < 0.5 => (near(rnd()), free),
                1 => (free, near(rnd())),
                _ => (near(rnd()), near(rnd())),
            };
            let length = 0.5 + 1.5 * rnd();
            let dir = cube_direction(face, s, t).map(|x| length * x);
            let da: [f64; 6] = std::array::from_fn(|_| (rnd() - 0.5) * 2.0 * length);
            let level = CubeLevelInput {
                uv_da: Some(da),
                bias: Some(rnd() - 0.5),
            };
            let dy: Vec<f64> = (0..c).map(|_| rnd() - 0.5).collect();
            // The kinks: texel centres and edges on every level (a face's edge among
            // them), integer λ (the clamp's ends among them), an isotropic footprint.
            let p = Projection::of(dir).unwrap();
            let st = p.clamped(dir);
            let lambda = cube_level_of_detail(dir, level, n);
            let [sx, sy, tx, ty] = cube_face_derivatives(dir, da).map(|d| d * n as f64);
            let (a, b, cc) = (sx * sx + tx * tx, sy * sy + ty * ty, sx * sy + tx * ty);
            let round = (0.25 * (a - b) * (a - b) + cc * cc).sqrt() < 1e-3 * (a + b);
            let kinked = stack.levels.iter().any(|l| {
                let m = l.width as f64;
                st.iter()
                    .any(|x| near_integer(x * m - 0.5, 1e-3) || near_integer(x * m, 1e-3))
            }) || (filter.uses_mips() && (near_integer(lambda, 1e-3) || round));
            if kinked {
                skipped += 1;
                continue;
            }
            // What the taps of the levels read did: another face, a corner.
            let used = match filter {
                Filter::Nearest => vec![],
                Filter::Linear => vec![0],
                _ => {
                    let (_, l0, l1, _) = cube_mip_levels(&stack, dir, level, filter);
                    vec![l0, l1]
                }
            };
            let taps: Vec<CubeTaps> = used
                .iter()
                .map(|&l| CubeTaps::new(&stack.levels[l], p.face, st))
                .collect();
            if taps.iter().any(|t| t.corner().is_some()) {
                corners += 1;
            }
            if taps
                .iter()
                .any(|t| t.texels.iter().flatten().any(|&(f, _, _)| f != p.face))
            {
                edges += 1;
            }
            let loss = |stack: &MipStack, dir: [f64; 3], level: CubeLevelInput| -> f64 {
                sample_cube(stack, 0, dir, level, filter)
                    .unwrap()
                    .iter()
                    .zip(&dy)
                    .map(|(a, b)| a * b)
                    .sum()
            };
            let mut tex_grad = stack.zero_grads();
            let g =
                sample_cube_backward(&stack, 0, dir, level, filter, &dy, &mut tex_grad).unwrap();
            let what = format!("{filter:?} dir {dir:?} (face {} at {st:?})", p.face);
            let mut check = |kind: usize, name: String, analytic: f64, numeric: f64| {
                let e = (analytic - numeric).abs();
                worst[kind] = worst[kind].max(e);
                assert!(e <= floor, "{what}: {name} {analytic} numeric {numeric}");
            };
            for k in 0..3 {
                let (mut a, mut b) = (dir, dir);
                a[k] += eps;
                b[k] -= eps;
                let num = (loss(&stack, a, level) - loss(&stack, b, level)) / (2.0 * eps);
                check(1, format!("d/ddir[{k}]"), g.dir[k], num);
            }
            for k in 0..6 {
                let (mut a, mut b) = (level, level);
                a.uv_da.as_mut().unwrap()[k] += eps;
                b.uv_da.as_mut().unwrap()[k] -= eps;
                let num = (loss(&stack, dir, a) - loss(&stack, dir, b)) / (2.0 * eps);
                check(2, format!("d/duv_da[{k}]"), g.uv_da[k], num);
            }
            let (mut a, mut b) = (level, level);
            a.bias = a.bias.map(|x| x + eps);
            b.bias = b.bias.map(|x| x - eps);
            let num = (loss(&stack, dir, a) - loss(&stack, dir, b)) / (2.0 * eps);
            check(3, "d/dbias".into(), g.bias, num);
            // The base texels, through the pyramid (the stack rebuilt each time).
            let to_base = stack.pyramid_backward(tex_grad);
            for i in 0..base.len() {
                let (mut a, mut b) = (base.clone(), base.clone());
                a[i] += eps;
                b[i] -= eps;
                let num = (loss(&stack_of(a, filter), dir, level)
                    - loss(&stack_of(b, filter), dir, level))
                    / (2.0 * eps);
                check(0, format!("d/dtex[{i}]"), to_base[i], num);
            }
            checked += 1;
        }
    }
    eprintln!(
        "{checked} checked, {skipped} skipped, {edges} across an edge, {corners} past a \
         corner; worst errors (tex, dir, uv_da, bias) {worst:?}"
    );
    assert!(
        checked >= 120 && skipped * 8 < checked && edges >= 40 && corners >= 15,
        "{checked} checked, {skipped} skipped, {edges} across an edge, {corners} past a corner"
    );
}

#[test]
fn cube_lookups_refuse_what_is_not_a_cube_map_and_read_each_items_cube() {
    let level = CubeLevelInput::default();
    let flat = MipStack::base(6, 4, 2, 1, vec![0.0; 48]).unwrap();
    assert!(sample_cube(&flat, 0, [1.0, 0.0, 0.0], level, Filter::Linear).is_err());
    let five = MipStack::base(5, 2, 2, 1, vec![0.0; 20]).unwrap();
    assert!(sample_cube(&five, 0, [1.0, 0.0, 0.0], level, Filter::Nearest).is_err());
    let two = random_cube(1, 2, 2, 1);
    assert!(sample_cube(&two, 2, [1.0, 0.0, 0.0], level, Filter::Nearest).is_err());
    let mut tex_grad = two.zero_grads();
    let wrong_dy = sample_cube_backward(
        &two,
        0,
        [1.0, 0.0, 0.0],
        level,
        Filter::Linear,
        &[1.0, 1.0],
        &mut tex_grad,
    );
    assert!(wrong_dy.is_err());
    // Each item reads its own cube; one cube serves every item.
    let nearest = |stack: &MipStack, item: usize| {
        sample_cube(stack, item, [0.1, -0.2, -1.0], level, Filter::Nearest).unwrap()[0]
    };
    let o = (6 + 5) * 4;
    let y = ((0.5 + 0.2 / 2.0) * 2.0) as usize;
    let x = ((0.5 - 0.1 / 2.0) * 2.0) as usize;
    assert_eq!(nearest(&two, 1), two.levels[0].texels[o + y * 2 + x]);
    let one = random_cube(1, 1, 2, 1);
    assert_eq!(nearest(&one, 0), nearest(&one, 7));
    // A direction with no face reads zero and takes no gradient.
    let mut tex_grad = one.zero_grads();
    let g = sample_cube_backward(
        &one,
        0,
        [0.0; 3],
        level,
        Filter::Linear,
        &[1.0],
        &mut tex_grad,
    )
    .unwrap();
    assert_eq!(g, CubeGrad::default());
    assert!(tex_grad.iter().flatten().all(|g| *g == 0.0));
    assert_eq!(
        sample_cube(&one, 0, [0.0; 3], level, Filter::Linear).unwrap(),
        [0.0]
    );
}
