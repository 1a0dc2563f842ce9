//! Tests of the 2D texture twin: each filter and boundary mode by hand, the mip stack, the
//! level, mode names, and the backward against central differences.

use super::bilinear::bilinear;
use super::*;

/// A 2 × 2 texture of one channel: texels 1, 2 (top row), 3, 4.
fn quad() -> MipStack {
    MipStack::base(1, 2, 2, 1, vec![1.0, 2.0, 3.0, 4.0]).unwrap()
}

fn one(stack: &MipStack, uv: [f64; 2], filter: Filter, boundary: Boundary) -> f64 {
    sample(
        stack,
        0,
        uv,
        LevelInput::default(),
        Mode { filter, boundary },
    )[0]
}

#[test]
fn nearest_reads_the_texel_under_uv_by_each_boundary() {
    let t = quad();
    assert_eq!(one(&t, [0.2, 0.2], Filter::Nearest, Boundary::Wrap), 1.0);
    assert_eq!(one(&t, [0.7, 0.2], Filter::Nearest, Boundary::Wrap), 2.0);
    assert_eq!(one(&t, [0.2, 0.7], Filter::Nearest, Boundary::Clamp), 3.0);
    // Wrap: u = −0.2 is u = 0.8; clamp holds the edge; zero reads nothing.
    assert_eq!(one(&t, [-0.2, 0.7], Filter::Nearest, Boundary::Wrap), 4.0);
    assert_eq!(one(&t, [-0.2, 0.7], Filter::Nearest, Boundary::Clamp), 3.0);
    assert_eq!(one(&t, [-0.2, 0.7], Filter::Nearest, Boundary::Zero), 0.0);
    assert_eq!(one(&t, [1.0, 0.7], Filter::Nearest, Boundary::Zero), 0.0);
    assert_eq!(one(&t, [1.0, 0.7], Filter::Nearest, Boundary::Clamp), 4.0);
    assert_eq!(
        one(&t, [f64::NAN, 0.7], Filter::Nearest, Boundary::Clamp),
        0.0
    );
}

#[test]
fn linear_blends_the_four_texels_around_uv_by_each_boundary() {
    let t = quad();
    // At a texel centre, the texel; at the texture's centre, the mean.
    assert_eq!(one(&t, [0.25, 0.25], Filter::Linear, Boundary::Clamp), 1.0);
    assert_eq!(one(&t, [0.5, 0.5], Filter::Linear, Boundary::Clamp), 2.5);
    // Halfway between the centres of texels 1 and 2: 1.5; a quarter of the way: 1.25.
    assert!((one(&t, [0.5, 0.25], Filter::Linear, Boundary::Wrap) - 1.5).abs() < 1e-15);
    assert!((one(&t, [0.375, 0.25], Filter::Linear, Boundary::Wrap) - 1.25).abs() < 1e-15);
    // u = 0 lies halfway between texel 2 (wrapped from the left) and texel 1.
    assert!((one(&t, [0.0, 0.25], Filter::Linear, Boundary::Wrap) - 1.5).abs() < 1e-15);
    // Clamp holds the edge texel's centre; zero blends the outside's zeros in.
    assert_eq!(one(&t, [0.0, 0.25], Filter::Linear, Boundary::Clamp), 1.0);
    assert!((one(&t, [0.0, 0.25], Filter::Linear, Boundary::Zero) - 0.5).abs() < 1e-15);
    assert_eq!(one(&t, [-1.0, 0.25], Filter::Linear, Boundary::Zero), 0.0);
    // Wrap is periodic in u and v.
    let a = one(&t, [0.3, 0.6], Filter::Linear, Boundary::Wrap);
    let b = one(&t, [2.3, -1.4], Filter::Linear, Boundary::Wrap);
    assert!((a - b).abs() < 1e-12, "{a} {b}");
}

#[test]
fn the_mip_stack_halves_each_extent_and_refuses_odd_ones() {
    // 4 wide, 2 high: 2 × 1, then 1 × 1 (the last from two texels side by side).
    let texels: Vec<f64> = (0..8).map(f64::from).collect();
    let s = MipStack::base(1, 2, 4, 1, texels)
        .unwrap()
        .build(None)
        .unwrap();
    assert_eq!(s.max_level(), 2);
    assert_eq!((s.levels[1].width, s.levels[1].height), (2, 1));
    assert_eq!(
        s.levels[1].texels,
        [(0.0 + 1.0 + 4.0 + 5.0) / 4.0, (2.0 + 3.0 + 6.0 + 7.0) / 4.0]
    );
    assert_eq!(s.levels[2].texels, [(2.5 + 4.5) / 2.0]);
    // max_mip_level limits the levels; an odd extent above 1 is an error unless not reached.
    let t = MipStack::base(1, 2, 4, 1, vec![0.0; 8]).unwrap();
    assert_eq!(t.clone().build(Some(1)).unwrap().max_level(), 1);
    let odd = MipStack::base(1, 6, 6, 1, vec![0.0; 36]).unwrap();
    assert_eq!(odd.clone().build(Some(1)).unwrap().levels[1].width, 3);
    let err = odd.build(None).unwrap_err().to_string();
    assert!(err.contains("odd extent"), "{err}");
    // Every channel and item averaged apart.
    let two = MipStack::base(2, 2, 2, 2, (0..16).map(f64::from).collect()).unwrap();
    let two = two.build(None).unwrap();
    assert_eq!(two.levels[1].texels, [3.0, 4.0, 11.0, 12.0]);
}

#[test]
fn the_level_follows_the_footprint_and_the_bias() {
    // Two texels a pixel along u: level 1; a footprint rotated 45°, the same length: 1.
    let d = LevelInput {
        uv_da: Some([2.0 / 8.0, 0.0, 0.0, 2.0 / 8.0]),
        bias: None,
    };
    assert!((level_of_detail(d, 8, 8) - 1.0).abs() < 1e-15);
    let r = 2.0 / 8.0 / 2f64.sqrt();
    let d = LevelInput {
        uv_da: Some([r, -r, r, r]),
        bias: Some(0.5),
    };
    assert!((level_of_detail(d, 8, 8) - 1.5).abs() < 1e-14);
    // Anisotropic: the major axis decides (4 texels along Y, 1 along X).
    let d = LevelInput {
        uv_da: Some([1.0 / 8.0, 0.0, 0.0, 4.0 / 8.0]),
        bias: None,
    };
    assert!((level_of_detail(d, 8, 8) - 2.0).abs() < 1e-15);
    // The bias alone.
    let d = LevelInput {
        uv_da: None,
        bias: Some(-0.25),
    };
    assert_eq!(level_of_detail(d, 8, 8), -0.25);
}

#[test]
fn mipmap_modes_read_the_levels_the_level_picks() {
    let texels: Vec<f64> = (0..16).map(|i| f64::from(i * i)).collect();
    let s = MipStack::base(1, 4, 4, 1, texels)
        .unwrap()
        .build(None)
        .unwrap();
    let uv = [0.3, 0.55];
    let at = |level: usize| bilinear(&s, 0, level, uv, Boundary::Clamp)[0];
    let with = |bias: f64, filter: Filter| {
        let level = LevelInput {
            uv_da: None,
            bias: Some(bias),
        };
        sample(
            &s,
            0,
            uv,
            level,
            Mode {
                filter,
                boundary: Boundary::Clamp,
            },
        )[0]
    };
    // λ = 1.5: the floor's level alone, or the two mixed halfway.
    assert_eq!(with(1.5, Filter::LinearMipmapNearest), at(1));
    assert!((with(1.5, Filter::LinearMipmapLinear) - 0.5 * (at(1) + at(2))).abs() < 1e-12);
    // Clamped to [0, the last level]; magnification reads level 0.
    assert_eq!(with(7.0, Filter::LinearMipmapLinear), at(2));
    assert_eq!(with(-3.0, Filter::LinearMipmapLinear), at(0));
    // A zero footprint (log2 0 = −∞) is magnification.
    let zero = LevelInput {
        uv_da: Some([0.0; 4]),
        bias: None,
    };
    assert_eq!(
        sample(
            &s,
            0,
            uv,
            zero,
            Mode {
                filter: Filter::LinearMipmapLinear,
                boundary: Boundary::Clamp
            }
        )[0],
        at(0)
    );
    // Linear never reads the levels.
    assert_eq!(with(1.5, Filter::Linear), at(0));
}

#[test]
fn modes_parse_as_nvdiffrast_names_them() {
    assert_eq!(Filter::parse("auto", false, None).unwrap(), Filter::Linear);
    assert_eq!(
        Filter::parse("auto", true, None).unwrap(),
        Filter::LinearMipmapLinear
    );
    assert_eq!(
        Filter::parse("linear-mipmap-linear", true, Some(0)).unwrap(),
        Filter::Linear
    );
    assert!(Filter::parse("linear-mipmap-nearest", false, None).is_err());
    assert!(Filter::parse("cubic", false, None).is_err());
    assert_eq!(Boundary::parse("zero").unwrap(), Boundary::Zero);
    assert!(Boundary::parse("cube").is_err());
    assert!(Boundary::parse("mirror").is_err());
    assert!(MipStack::base(1, 2, 2, 1, vec![0.0; 3]).is_err());
    assert!(MipStack::base(1, 0, 2, 1, vec![]).is_err());
}

/// A deterministic pseudo-random stream in [0, 1).
pub(super) fn stream(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Whether `x` lies within `margin` of an integer (a kink of the piecewise forward).
pub(super) fn near_integer(x: f64, margin: f64) -> bool {
    (x - x.round()).abs() < margin
}

/// Every gradient of one pixel against central differences of the forward, per component,
/// on an 8 × 4 texture of 3 channels and its mip stack, in every filter and boundary mode,
/// away from the kinks (counted: the draws skipped).
#[test]
fn the_backward_matches_central_differences_in_every_mode() {
    let mut rnd = stream(7);
    let (w, h, c) = (8usize, 4usize, 3usize);
    let base: Vec<f64> = (0..w * h * c).map(|_| rnd()).collect();
    let stack_of = |texels: Vec<f64>, filter: Filter| {
        let s = MipStack::base(1, h, w, c, texels).unwrap();
        if filter.uses_mips() {
            s.build(None).unwrap()
        } else {
            s
        }
    };
    let eps = 1e-6;
    let bound =
        |analytic: f64, numeric: f64| (analytic - numeric).abs() <= 1e-6 * (1.0 + numeric.abs());
    let (mut checked, mut skipped) = (0, 0);
    for filter in [
        Filter::Nearest,
        Filter::Linear,
        Filter::LinearMipmapNearest,
        Filter::LinearMipmapLinear,
    ] {
        for boundary in [Boundary::Wrap, Boundary::Clamp, Boundary::Zero] {
            let stack = stack_of(base.clone(), filter);
            for _ in 0..12 {
                let uv = [rnd() * 1.6 - 0.3, rnd() * 1.6 - 0.3];
                let level = LevelInput {
                    uv_da: Some([
                        (rnd() - 0.3) * 0.6,
                        (rnd() - 0.5) * 0.2,
                        (rnd() - 0.5) * 0.2,
                        (rnd() - 0.3) * 0.9,
                    ]),
                    bias: Some(rnd() - 0.5),
                };
                let dy: Vec<f64> = (0..c).map(|_| rnd() - 0.5).collect();
                // The kinks: texel-centre fractions at every level, integer λ, the clamp.
                let lambda = level_of_detail(level, w, h);
                let kinked = (0..stack.levels.len()).any(|l| {
                    let lw = stack.levels[l].width as f64;
                    let lh = stack.levels[l].height as f64;
                    let (u, v) = (uv[0] - uv[0].floor(), uv[1] - uv[1].floor());
                    near_integer(uv[0] * lw - 0.5, 1e-3)
                        || near_integer(uv[1] * lh - 0.5, 1e-3)
                        || near_integer(u * lw, 1e-3)
                        || near_integer(v * lh, 1e-3)
                        || near_integer(uv[0] * lw, 1e-3)
                        || near_integer(uv[1] * lh, 1e-3)
                }) || near_integer(lambda, 1e-3)
                    || near_integer(lambda - stack.max_level() as f64, 1e-3);
                if kinked {
                    skipped += 1;
                    continue;
                }
                let loss = |stack: &MipStack, uv: [f64; 2], level: LevelInput| -> f64 {
                    sample(stack, 0, uv, level, Mode { filter, boundary })
                        .iter()
                        .zip(&dy)
                        .map(|(a, b)| a * b)
                        .sum()
                };
                let mut tex_grad = stack.zero_grads();
                let g = sample_backward(
                    &stack,
                    0,
                    uv,
                    level,
                    Mode { filter, boundary },
                    &dy,
                    &mut tex_grad,
                );
                let what = format!("{filter:?} {boundary:?} uv {uv:?}");
                for k in 0..2 {
                    let (mut a, mut b) = (uv, uv);
                    a[k] += eps;
                    b[k] -= eps;
                    let n = (loss(&stack, a, level) - loss(&stack, b, level)) / (2.0 * eps);
                    assert!(
                        bound(g.uv[k], n),
                        "{what}: d/duv[{k}] {} numeric {n}",
                        g.uv[k]
                    );
                }
                for k in 0..4 {
                    let (mut a, mut b) = (level, level);
                    a.uv_da.as_mut().unwrap()[k] += eps;
                    b.uv_da.as_mut().unwrap()[k] -= eps;
                    let n = (loss(&stack, uv, a) - loss(&stack, uv, b)) / (2.0 * eps);
                    assert!(
                        bound(g.uv_da[k], n),
                        "{what}: d/duv_da[{k}] {} numeric {n}",
                        g.uv_da[k]
                    );
                }
                let (mut a, mut b) = (level, level);
                a.bias = a.bias.map(|x| x + eps);
                b.bias = b.bias.map(|x| x - eps);
                let n = (loss(&stack, uv, a) - loss(&stack, uv, b)) / (2.0 * eps);
                assert!(bound(g.bias, n), "{what}: d/dbias {} numeric {n}", g.bias);
                // The base texture's texels, through the pyramid (the stack rebuilt each time).
                let to_base = stack.pyramid_backward(tex_grad);
                for i in 0..base.len() {
                    let (mut a, mut b) = (base.clone(), base.clone());
                    a[i] += eps;
                    b[i] -= eps;
                    let n = (loss(&stack_of(a, filter), uv, level)
                        - loss(&stack_of(b, filter), uv, level))
                        / (2.0 * eps);
                    assert!(
                        bound(to_base[i], n),
                        "{what}: d/dtex[{i}] {} numeric {n}",
                        to_base[i]
                    );
                }
                checked += 1;
            }
        }
    }
    assert!(
        checked >= 100 && skipped * 4 < checked,
        "{checked} checked, {skipped} skipped"
    );
}

/// The level's gradient is zero where the footprint is isotropic (0/0), as nvdiffrast's.
#[test]
fn an_isotropic_footprint_gives_the_level_no_gradient() {
    assert_eq!(level_gradient([0.25, 0.0, 0.0, 0.25], 8, 8), [0.0; 4]);
    assert_eq!(level_gradient([0.0; 4], 8, 8), [0.0; 4]);
    assert!(
        level_gradient([0.25, 0.0, 0.0, 0.5], 8, 8)
            .iter()
            .any(|g| *g != 0.0)
    );
}

#[test]
fn a_shared_texture_serves_every_minibatch_item() {
    let t = quad();
    let mode = Mode {
        filter: Filter::Linear,
        boundary: Boundary::Wrap,
    };
    let at = |item| sample(&t, item, [0.4, 0.6], LevelInput::default(), mode);
    let (a, b) = (at(0), at(3));
    assert_eq!(a, b);
}
