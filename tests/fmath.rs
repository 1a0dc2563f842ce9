//! softvk's own maths (`kernels/gpu/include/fmath.glsl`) against its CPU twin (`softvk::fmath`), bit
//! for bit, and the twin against f64.
//!
//! The device check covers, for every function, 2^24 inputs: every sign and exponent (all 512
//! combinations of the top 9 bits) with 2^15 mantissas each, plus the specials (±0, subnormals,
//! ±∞, NaN, the largest and smallest normals, the overflow and underflow thresholds). The run over
//! all 2^32 inputs of each unary function is `exhaustive_unary_functions_equal_their_twin`
//! (ignored: about a minute per function on lavapipe; `cargo test --release --test fmath --
//! --ignored`); every run checks one 64th of it (`a_slice_of_every_unary_functions_inputs_equals_its_twin`,
//! the slice picked by the commit).

mod common;

use softvk::fmath::{self, Eval, Function};

/// 2^24 bit patterns: every sign and exponent, 2^15 mantissas each (a stride of 2^8, offset by a
/// hash so that low bits vary).
fn stratified() -> Vec<f32> {
    let mut out = Vec::with_capacity(1 << 24);
    for top in 0u32..512 {
        for m in 0u32..(1 << 15) {
            let low = m.wrapping_mul(2_654_435_761) >> 24; // 8 varying low bits
            out.push(f32::from_bits((top << 23) | (m << 8) | low));
        }
    }
    out
}

fn specials() -> Vec<f32> {
    let mut v = vec![
        0.0,
        -0.0,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        f32::MIN_POSITIVE,
        -f32::MIN_POSITIVE,
        f32::from_bits(1),
        f32::from_bits(0x8000_0001),
        f32::from_bits(0x007f_ffff),
        f32::MAX,
        f32::MIN,
        1.0,
        -1.0,
        88.722_84,
        88.722_84,
        -87.336_55,
        -87.336_54,
        f32::from_bits(0xc2ae_ac4f), // the least float whose exp is normal
        -87.2,
        -87.0,
        -17.0,
        9.0,
        16_777_216.0,
        -16_777_216.0,
        2f32.powi(126),
        2f32.powi(125),
        2f32.powi(-126),
    ];
    // Neighbours of each.
    let around: Vec<f32> = v
        .iter()
        .filter(|x| x.is_finite())
        .flat_map(|x| {
            [
                f32::from_bits(x.to_bits() + 1),
                f32::from_bits(x.to_bits().wrapping_sub(1)),
            ]
        })
        .collect();
    v.extend(around);
    v
}

/// The same bits, or both NaN (payloads are not promised).
fn same(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

fn check(eval: &Eval, gpu: &common::Gpu, f: Function, a: &[f32], b: &[f32]) -> usize {
    let got = eval.run(gpu, f, a, b).expect("fmath on the device");
    let mut bad = Vec::new();
    for (i, &g) in got.iter().enumerate() {
        let y = if b.is_empty() { 0.0 } else { b[i] };
        let want = f.eval(a[i], y);
        if !same(g, want) {
            bad.push(format!(
                "{}({:e} [{:#010x}], {y:e}): device {g:e} [{:#010x}], twin {want:e} [{:#010x}]",
                f.name(),
                a[i],
                a[i].to_bits(),
                g.to_bits(),
                want.to_bits()
            ));
        }
    }
    assert!(
        bad.is_empty(),
        "{} of {} differ, first: {}",
        bad.len(),
        a.len(),
        bad[..bad.len().min(5)].join("\n")
    );
    a.len()
}

/// A second argument for each first: every exponent near the first's (so quotients and powers
/// stay mostly finite) with hashed mantissas.
fn partners(a: &[f32], f: Function) -> Vec<f32> {
    a.iter()
        .enumerate()
        .map(|(i, x)| {
            let h = (i as u32).wrapping_mul(2_246_822_519).rotate_left(13);
            match f {
                Function::Pow => {
                    f32::from_bits((h & 0x807f_ffff) | ((120 + (h >> 28)) << 23)) * 4.0
                }
                _ => {
                    let e = ((x.to_bits() >> 23) & 0xff) as i32 + (h >> 27) as i32 - 16;
                    f32::from_bits((h & 0x807f_ffff) | ((e.clamp(0, 255) as u32) << 23))
                }
            }
        })
        .collect()
}

#[test]
fn every_function_equals_its_twin_on_the_device() {
    let Some(gpu) = common::gpu() else { return };
    let eval = Eval::new(&gpu).unwrap();
    let mut inputs = stratified();
    inputs.extend(specials());
    for f in Function::ALL {
        if f.binary() {
            let b = partners(&inputs, f);
            check(&eval, &gpu, f, &inputs, &b);
            // Every special against every special.
            let s = specials();
            let (x, y): (Vec<f32>, Vec<f32>) = s
                .iter()
                .flat_map(|&x| s.iter().map(move |&y| (x, y)))
                .unzip();
            check(&eval, &gpu, f, &x, &y);
        } else {
            let mut own: Vec<f32> = inputs.iter().copied().filter(|&x| f.domain(x)).collect();
            if f == Function::Rcp1To2 {
                // Its whole domain: every float of [1, 2].
                own.extend((0..1u32 << 23).map(|m| f32::from_bits(0x3f80_0000 | m)));
            }
            check(&eval, &gpu, f, &own, &[]);
        }
    }
}

/// Every input of one unary function in `chunks` (of 2^24 bit patterns each, 256 in all) on the
/// device against the twin; the number of inputs of its domain checked.
fn chunks_equal_their_twin(
    eval: &Eval,
    gpu: &common::Gpu,
    f: Function,
    chunks: impl Iterator<Item = u64>,
) -> usize {
    let chunk = 1u64 << 24;
    let mut done = 0;
    for c in chunks {
        let a: Vec<f32> = (c * chunk..(c + 1) * chunk)
            .map(|b| f32::from_bits(b as u32))
            .filter(|&x| f.domain(x))
            .collect();
        done += check(eval, gpu, f, &a, &[]);
    }
    done
}

fn unary() -> impl Iterator<Item = Function> {
    Function::ALL.into_iter().filter(|f| !f.binary())
}

/// A part of the exhaustive run on every run: 2^26 consecutive inputs of every unary function,
/// the slice (one of 64) picked by the commit being tested, so that over many commits every
/// input is seen. `FMATH_SLICE=k` (0–63) picks one by hand; with no git checkout (a packaged
/// crate) the slice is 0. It prints the slice, so that a failure can be rerun.
#[test]
fn a_slice_of_every_unary_functions_inputs_equals_its_twin() {
    let Some(gpu) = common::gpu() else { return };
    let eval = Eval::new(&gpu).unwrap();
    let slice = match std::env::var("FMATH_SLICE") {
        Ok(k) => k.parse::<u64>().expect("FMATH_SLICE is a number 0–63") % 64,
        Err(_) => std::process::Command::new("git")
            .args(["rev-parse", "HEAD"])
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .ok()
            .filter(|o| o.status.success())
            .and_then(|o| u64::from_str_radix(&String::from_utf8_lossy(&o.stdout)[..8], 16).ok())
            .map_or(0, |h| h % 64),
    };
    let (first, last) = (slice << 26, ((slice + 1) << 26) - 1);
    eprintln!(
        "fmath: slice {slice} of 64 (FMATH_SLICE={slice}): bit patterns {first:#010x}..={last:#010x}"
    );
    for f in unary() {
        let n = chunks_equal_their_twin(&eval, &gpu, f, slice * 4..slice * 4 + 4);
        eprintln!("{}: {n} inputs equal", f.name());
    }
}

#[test]
#[ignore = "all 2^32 inputs of each unary function: minutes each; run by hand"]
fn exhaustive_unary_functions_equal_their_twin() {
    // `FMATH_ONLY=exp,log` limits the run to those functions.
    let only = std::env::var("FMATH_ONLY").ok();
    let Some(gpu) = common::gpu() else { return };
    let eval = Eval::new(&gpu).unwrap();
    let chosen = unary().filter(|f| {
        only.as_deref()
            .is_none_or(|o| o.split(',').any(|n| n == f.name()))
    });
    for f in chosen {
        let start = std::time::Instant::now();
        let mut done = 0;
        for c in 0..256 {
            done += chunks_equal_their_twin(&eval, &gpu, f, c..c + 1);
            if c % 32 == 31 {
                eprintln!(
                    "{}: {} of 256 chunks ({:.0} s)",
                    f.name(),
                    c + 1,
                    start.elapsed().as_secs_f64()
                );
            }
        }
        eprintln!(
            "{}: all {done} inputs of its domain equal ({:.0} s)",
            f.name(),
            start.elapsed().as_secs_f64()
        );
    }
}

/// |y − reference| in units in the last place of the reference rounded to f32.
fn ulps(y: f32, reference: f64) -> f64 {
    let r = reference as f32;
    let e = if r == 0.0 || r.abs() < f32::MIN_POSITIVE {
        -126
    } else {
        ((r.to_bits() >> 23) & 0xff) as i32 - 127
    };
    (f64::from(y) - reference).abs() / 2f64.powi(e - 23)
}

/// The worst error in ulps over `inputs` (where the reference is finite and normal).
fn worst(f: Function, inputs: impl Iterator<Item = (f32, f32)>) -> (f64, f32) {
    let mut w = (0.0, 0.0);
    for (x, y) in inputs {
        let r = f.reference(f64::from(x), f64::from(y));
        if !r.is_finite() || r.abs() < f64::from(f32::MIN_POSITIVE) || r.abs() > f64::from(f32::MAX)
        {
            continue;
        }
        let u = if matches!(f, Function::Sin | Function::Cos) {
            // Absolute, in units of 2^-24 (ulps of 1): relative error means nothing near a zero.
            (f64::from(f.eval(x, y)) - r).abs() * 2f64.powi(24)
        } else {
            ulps(f.eval(x, y), r)
        };
        if u > w.0 {
            w = (u, x);
        }
    }
    w
}

/// Every float in [lo, hi) with bit-pattern step `step`.
fn range(lo: f32, hi: f32, step: u32) -> impl Iterator<Item = f32> {
    let (a, b) = (lo.to_bits(), hi.to_bits());
    assert!(lo >= 0.0 && a < b);
    (a..b).step_by(step as usize).map(f32::from_bits)
}

/// exp's last normal results: every float of (−126 ln 2, −87] gets its result within an ulp
/// (all 44 112 of them), the least of them a normal result, the float below it 0.
#[test]
fn exp_is_accurate_down_to_its_least_normal_result() {
    let least = f32::from_bits(0xc2ae_ac4f);
    assert!(f64::from(least) > -126.0 * std::f64::consts::LN_2);
    let below = f32::from_bits(0xc2ae_ac50);
    assert!(f64::from(below) < -126.0 * std::f64::consts::LN_2);
    assert_eq!(fmath::exp(below), 0.0);
    assert!(fmath::exp(least) >= f32::MIN_POSITIVE);
    let edge = (0xc2ae_0000u32..=0xc2ae_ac4f).map(f32::from_bits);
    let (u, at) = worst(Function::Exp, edge.map(|x| (x, 0.0)));
    eprintln!("exp on (−126 ln 2, −87]: worst {u:.3} ulp at {at:e}");
    assert!(u <= 1.0, "exp: {u} ulps at {at:e}");
    for x in (0xc2ae_0000u32..=0xc2ae_ac4f).map(f32::from_bits) {
        assert!(
            fmath::exp(x) >= f32::MIN_POSITIVE,
            "exp({x:e}) = {:e}",
            fmath::exp(x)
        );
    }
}

#[test]
fn the_twin_is_accurate_against_f64() {
    let report = |f: Function, bound: f64, (u, at): (f64, f32)| {
        eprintln!("{}: worst {u:.3} ulp at {at:e}", f.name());
        assert!(
            u <= bound,
            "{}: {u} ulps at {at:e} (bound {bound})",
            f.name()
        );
    };
    // (function, bound in ulps, every 61st or 97th float of [lo, hi) and its negation).
    // rcp is 0 from 2^126 by definition: its range stops short of that. exp's results below
    // 2^-126 (from −126 ln 2 down) are 0 by definition and left out by `worst`; from there up
    // every result is normal and held to the bound.
    let table: [(Function, f64, f32, f32, u32); 11] = [
        (Function::Rcp, 1.2, f32::MIN_POSITIVE, 8.5e37, 97),
        (Function::Sqrt, 0.8, f32::MIN_POSITIVE, f32::MAX, 97),
        (Function::Exp, 1.0, f32::MIN_POSITIVE, 88.7, 61),
        // 1.5 before Cephes's shorter minimax (d0dc91a): it measures 1.526 at 0.3708 (k = 1,
        // twice the reduced polynomial's error), which only a longer polynomial would lower.
        (Function::Expm1, 1.6, f32::MIN_POSITIVE, 88.7, 61),
        (Function::Log, 1.0, f32::MIN_POSITIVE, f32::MAX, 97),
        (Function::Sigmoid, 3.0, f32::MIN_POSITIVE, 80.0, 61),
        (Function::SigmoidGrad, 6.0, f32::MIN_POSITIVE, 80.0, 61),
        (Function::Tanh, 3.5, f32::MIN_POSITIVE, 12.0, 61),
        // sin and cos: absolute error in units of 2^-24 (`worst`).
        (Function::Sin, 2.0, 1e-30, 8192.0, 61),
        (Function::Cos, 2.0, 1e-30, 8192.0, 61),
        (Function::Div, 2.0, 1e-30, 1e30, 997),
    ];
    for (f, bound, lo, hi, step) in table {
        let positive_only = matches!(f, Function::Sqrt | Function::Log);
        let inputs = range(lo, hi, step)
            .flat_map(|x| [x, -x])
            .filter(|x| !positive_only || *x > 0.0)
            .enumerate()
            .map(|(i, x)| (x, 0.37 + (i % 1000) as f32 * 1.7));
        report(f, bound, worst(f, inputs));
    }
    // div_rn is IEEE division: equal to f32 `/` on 4 million pairs of hashed bit patterns (every
    // exponent, subnormals included) and on mantissas near 1 and 2, except where the quotient is
    // subnormal (rounded twice there, and zero on a flushing device: not promised).
    let hashed = |i: u32, salt: u32| {
        f32::from_bits(
            i.wrapping_mul(2_654_435_761)
                .wrapping_add(salt)
                .rotate_left(11)
                .wrapping_mul(2_246_822_519),
        )
    };
    let edges = [
        1.0f32,
        2.0,
        3.0,
        1.5,
        1.999_999_9,
        1.000_000_1,
        0.75,
        0.0,
        -0.0,
        f32::INFINITY,
        f32::MAX,
        f32::MIN_POSITIVE,
        f32::from_bits(1),
        f32::NAN,
    ];
    let pairs = (0..1u32 << 22)
        .map(|i| (hashed(i, 1), hashed(i, 7)))
        .chain(
            edges
                .iter()
                .flat_map(|&x| edges.iter().map(move |&y| (x, y))),
        )
        .filter(|(x, y)| !((x / y).abs() < f32::MIN_POSITIVE && x / y != 0.0));
    for (x, y) in pairs {
        let got = fmath::div_rn(x, y);
        let want = x / y;
        assert!(
            got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
            "div_rn({x:e}, {y:e}) = {got:e}, IEEE {want:e}"
        );
    }
    // exp(y ln x) carries ln x's rounding times |y ln x| (up to about 20 here): tens of ulps, as
    // Vulkan's own pow (inherited from exp2(y log2 x)). Only the probe's p-norm uses it.
    let powers = range(1e-3, 1e3, 97)
        .enumerate()
        .map(|(i, x)| (x, -3.0 + (i % 600) as f32 * 0.01));
    report(Function::Pow, 32.0, worst(Function::Pow, powers));
    // The vector helpers: a fixed order, no driver choice.
    assert_eq!(fmath::dot3([1.0, 2.0, 3.0], [4.0, 5.0, 6.0]), 32.0);
    assert_eq!(fmath::length3([3.0, 4.0, 12.0]), 13.0);
}
