//! softvk's float maths, the CPU twin of `kernels/gpu/include/fmath.glsl`, operation for operation.
//!
//! Vulkan requires f32 addition, subtraction and multiplication to be correctly rounded, but
//! leaves `exp`, `log`, `pow`, division, `sqrt`, `sin`, `cos` and the summation order of `dot` and
//! matrix products to each driver. Every kernel uses these functions instead, built from the
//! correctly rounded operations, comparisons and exact bit manipulation, so a kernel's result is
//! the same bits on any conformant device, and equals these functions evaluated here (Rust never
//! fuses `a * b + c`). `tests/fmath.rs` checks the GPU against this module bit for bit, and this
//! module against f64.
//!
//! Subnormals: inputs below 2⁻¹²⁶ in magnitude are read as zero and results that would fall below
//! it are returned as zero, decided by comparisons, so flushing and keeping devices agree.
//! NaN results are NaN, but their payload bits are not promised.

// The constants are written as in `fmath.glsl`, digit for digit, so that both round the same
// decimal to the same f32.
#![allow(clippy::excessive_precision)]

const MIN_NORMAL: f32 = f32::MIN_POSITIVE;

/// 2^k for −126 ≤ k ≤ 127, from its bits.
fn pow2(k: i32) -> f32 {
    f32::from_bits(((k + 127) as u32) << 23)
}

/// `x`, or a zero of `x`'s sign when `|x|` is below the normal range.
pub fn ftz(x: f32) -> f32 {
    if x.abs() < MIN_NORMAL {
        f32::from_bits(x.to_bits() & 0x8000_0000)
    } else {
        x
    }
}

/// The mantissa of a normal `bits` as a float in [1, 2).
fn mantissa(bits: u32) -> f32 {
    f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000)
}

/// 1 / x (Newton's iteration on the mantissa from a linear start, then the exponent).
pub fn rcp(x: f32) -> f32 {
    let bits = x.to_bits();
    let sign = bits & 0x8000_0000;
    let mag = bits & 0x7fff_ffff;
    if mag < 0x0080_0000 {
        return f32::from_bits(sign | 0x7f80_0000); // zero and subnormal
    }
    if mag >= 0x7e80_0000 {
        // From 2^126 (|1/x| ≤ 2^-126) and infinite: a signed zero; NaN stays.
        return if mag > 0x7f80_0000 {
            x
        } else {
            f32::from_bits(sign)
        };
    }
    let m = mantissa(bits);
    let mut y = 1.411_764_7 - 0.470_588_24 * m;
    for _ in 0..3 {
        y = y + y * (1.0 - m * y);
    }
    // y · 2^-e by y's exponent field: normal for e ≤ 125.
    f32::from_bits(((y.to_bits() + 0x3f80_0000) - (bits & 0x7f80_0000)) | sign)
}

/// a / b as a · (1 / b).
pub fn div(a: f32, b: f32) -> f32 {
    ftz(ftz(a) * rcp(b))
}

/// Dekker's exact product: p + e = x y.
fn two_product(x: f32, y: f32) -> (f32, f32) {
    let p = x * y;
    let cx = 4097.0 * x;
    let xh = cx - (cx - x);
    let xl = x - xh;
    let cy = 4097.0 * y;
    let yh = cy - (cy - y);
    let yl = y - yh;
    (p, ((xh * yh - p) + xh * yl + xl * yh) + xl * yl)
}

/// |x| = m · 2^e with m ∈ [1, 2), from the bits (subnormals normalised); x finite, nonzero.
fn frexp(x: f32) -> (f32, i32) {
    let bits = x.to_bits() & 0x7fff_ffff;
    let field = bits >> 23;
    let mant = bits & 0x007f_ffff;
    if field == 0 {
        let shift = 23 - (31 - (mant | 1).leading_zeros() as i32);
        (
            f32::from_bits(((mant << shift) & 0x007f_ffff) | 0x3f80_0000),
            -126 - shift,
        )
    } else {
        (f32::from_bits(mant | 0x3f80_0000), field as i32 - 127)
    }
}

/// a / b correctly rounded: IEEE division, for kernels that must equal another library's bit for
/// bit (PyTorch3D's). Subnormal operands count; a quotient below 2⁻¹²⁶ is rounded twice.
pub fn div_rn(a: f32, b: f32) -> f32 {
    let (a_zero, b_zero) = (a.abs() == 0.0, b.abs() == 0.0);
    let (a_inf, b_inf) = (a.is_infinite(), b.is_infinite());
    let y = if a.is_nan() || b.is_nan() || (a_zero && b_zero) || (a_inf && b_inf) {
        f32::NAN
    } else if a_zero || b_inf {
        0.0
    } else if b_zero || a_inf {
        f32::INFINITY
    } else {
        let ((aa, ea), (ab, eb)) = (frexp(a), frexp(b));
        let r = rcp(ab);
        let mut q = aa * r;
        let (p, e) = two_product(q, ab);
        q += ((aa - p) - e) * r;
        let (p, e) = two_product(q, ab);
        let rem = (aa - p) - e;
        let bits = q.to_bits();
        let up = f32::from_bits(bits + 1);
        let down = f32::from_bits(bits - 1);
        let above = rem - ((up - q) * 0.5) * ab;
        let below = rem + ((q - down) * 0.5) * ab;
        let odd = bits & 1 != 0;
        let q = if rem > 0.0 {
            if above > 0.0 || (above == 0.0 && odd) {
                up
            } else {
                q
            }
        } else if below < 0.0 || (below == 0.0 && odd) {
            down
        } else {
            q
        };
        let k = ea - eb;
        if k < -189 {
            0.0
        } else if k > 127 {
            (q * pow2(127)) * pow2((k - 127).min(127))
        } else if k >= -126 {
            q * pow2(k)
        } else {
            (q * pow2(k + 64)) * pow2(-64)
        }
    };
    if (a.to_bits() ^ b.to_bits()) >= 0x8000_0000 {
        -y
    } else {
        y
    }
}

/// √x: an inverse square root by Newton's iteration on m ∈ [1, 4), then one correction.
pub fn sqrt(x: f32) -> f32 {
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    if !(x >= MIN_NORMAL) {
        return if x >= 0.0 || x.abs() < MIN_NORMAL {
            0.0
        } else {
            f32::NAN
        };
    }
    if x == f32::INFINITY {
        return x;
    }
    let bits = x.to_bits();
    let e = (bits >> 23) as i32 - 127;
    let odd = e & 1;
    let mut m = mantissa(bits);
    if odd == 1 {
        m *= 2.0;
    }
    let mut y = 1.0 - 0.15 * m;
    for _ in 0..4 {
        y *= 1.5 - 0.5 * m * y * y;
    }
    let mut s = m * y;
    s += 0.5 * y * (m - s * s);
    s * pow2((e - odd) / 2)
}

/// exp(r) − 1 = r + r² P(r) on the reduced range, P Cephes's minimax.
fn expm1_reduced(r: f32) -> f32 {
    let mut p = 1.987_569_150_0e-4_f32;
    p = 1.398_199_950_7e-3 + r * p;
    p = 8.333_451_907_3e-3 + r * p;
    p = 4.166_579_589_4e-2 + r * p;
    p = 1.666_666_545_9e-1 + r * p;
    p = 5.000_000_120_1e-1 + r * p;
    r + (r * r) * p
}

const LN2_HI: f32 = 0.693_145_751_953_125;
const LN2_LO: f32 = 1.428_606_765_330_187e-6;
const LOG2E: f32 = std::f32::consts::LOG2_E; // GLSL's 1.44269504: the same f32

/// k = round(x / ln 2) and r = x − k ln 2.
fn reduce_ln2(x: f32) -> (f32, i32) {
    let kf = (x * LOG2E + 0.5).floor();
    ((x - kf * LN2_HI) - kf * LN2_LO, kf as i32)
}

/// The least float whose exp is normal, just above −126 ln 2 (`FM_EXP_MIN`).
const EXP_MIN: f32 = -87.336_540_2;

/// exp(x): 0 below `EXP_MIN`, just above −126 ln 2 (no subnormal results), +∞ above ln(f32::MAX).
pub fn exp(x: f32) -> f32 {
    if x.is_nan() {
        return x;
    }
    if x > 88.722_839_4 {
        return f32::INFINITY;
    }
    if x < EXP_MIN {
        return 0.0;
    }
    let (r, k) = reduce_ln2(x);
    let p = 1.0 + expm1_reduced(r);
    if k > 127 {
        (p * 2.0) * pow2(k - 1)
    } else {
        p * pow2(k)
    }
}

/// exp(x) − 1, without cancellation near zero.
pub fn expm1(x: f32) -> f32 {
    if x.is_nan() || x > 88.722_839_4 {
        return exp(x);
    }
    if x < -17.0 {
        return -1.0;
    }
    let (r, k) = reduce_ln2(ftz(x));
    let q = expm1_reduced(r);
    if k == 0 {
        return q;
    }
    let t = if k > 127 { 2.0 * pow2(k - 1) } else { pow2(k) };
    if k <= 24 {
        (t - 1.0) + t * q
    } else {
        (t + t * q) - 1.0
    }
}

const LOG_LN2_HI: f32 = 6.931_381_225_6e-1;
const LOG_LN2_LO: f32 = 9.058_000_614_5e-6;

/// ln(x), after FreeBSD's `logf`: −∞ for zero and subnormals, NaN below zero.
pub fn log(x: f32) -> f32 {
    if x.is_nan() || x == f32::INFINITY {
        return x;
    }
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    if !(x >= MIN_NORMAL) {
        return if x.abs() < MIN_NORMAL {
            f32::NEG_INFINITY
        } else {
            f32::NAN
        };
    }
    let bits = x.to_bits();
    let mut k = (bits >> 23) as i32 - 127;
    let mut m = mantissa(bits);
    if m > 1.414_213_54 {
        m *= 0.5;
        k += 1;
    }
    let f = m - 1.0;
    let s = f * rcp(2.0 + f);
    let z = s * s;
    let w = z * z;
    let t1 = w * (0.400_009_721_52 + w * 0.242_790_788_41);
    let t2 = z * (0.666_666_626_93 + w * 0.284_987_866_88);
    let r = t2 + t1;
    let hfsq = 0.5 * f * f;
    let dk = k as f32;
    dk * LOG_LN2_HI - ((hfsq - (s * (hfsq + r) + dk * LOG_LN2_LO)) - f)
}

/// 1 / (1 + exp(−x)) from e = exp(−|x|): 1 / (1 + e) for x ≥ 0, e / (1 + e) below.
pub fn sigmoid(x: f32) -> f32 {
    let e = exp(-x.abs());
    let r = rcp(1.0 + e);
    if x >= 0.0 { r } else { e * r }
}

/// sigmoid′(x) = e / (1 + e)², e = exp(−|x|).
pub fn sigmoid_grad(x: f32) -> f32 {
    let e = exp(-x.abs());
    let r = rcp(1.0 + e);
    e * r * r
}

/// tanh(x) = e / (e + 2) with e = expm1(2|x|), odd; ±1 beyond |x| = 9.
pub fn tanh(x: f32) -> f32 {
    if x.is_nan() {
        return x;
    }
    let a = x.abs();
    let t = if a > 9.0 {
        1.0
    } else {
        let e = expm1(2.0 * a);
        div(e, e + 2.0)
    };
    if x < 0.0 { -t } else { t }
}

/// x^y for x ≥ 0 as exp(y ln x); 0^y is 0 for y > 0, and x⁰ is 1.
pub fn pow(x: f32, y: f32) -> f32 {
    if y == 0.0 {
        return 1.0;
    }
    if x.abs() < MIN_NORMAL {
        return if y > 0.0 { 0.0 } else { f32::INFINITY };
    }
    exp(y * log(x))
}

const PIO2_1: f32 = 1.570_312_5;
const PIO2_2: f32 = 4.837_512_969_970_703_125e-4;
const PIO2_3: f32 = 7.549_789_954_891_882_16e-8;

/// (sin x, cos x): x reduced by π/2 in three parts, then Cephes's polynomials.
pub fn sincos(x: f32) -> (f32, f32) {
    if x.is_nan() || x.abs() == f32::INFINITY {
        return (f32::NAN, f32::NAN);
    }
    let a = ftz(x);
    let jf = (a * std::f32::consts::FRAC_2_PI + 0.5).floor(); // GLSL's 0.636619772
    let r = ((a - jf * PIO2_1) - jf * PIO2_2) - jf * PIO2_3;
    let z = r * r;
    let s = ((-1.951_529_589_1e-4 * z + 8.332_160_873_6e-3) * z - 1.666_665_461_1e-1) * z * r + r;
    let c = ((2.443_315_711_809_948e-5 * z - 1.388_731_625_493_765e-3) * z
        + 4.166_664_568_298_827e-2)
        * z
        * z
        - 0.5 * z
        + 1.0;
    let q = if jf.abs() < 16_777_216.0 {
        (jf as i32 & 3) as u32
    } else {
        0
    };
    let (mut sn, mut cs) = if q & 1 == 0 { (s, c) } else { (c, s) };
    if q & 2 != 0 {
        sn = -sn;
    }
    if (q + 1) & 2 != 0 {
        cs = -cs;
    }
    (sn, cs)
}

/// sin x.
pub fn sin(x: f32) -> f32 {
    sincos(x).0
}

/// cos x.
pub fn cos(x: f32) -> f32 {
    sincos(x).1
}

/// a · b summed ((x + y) + z).
pub fn dot3(a: [f32; 3], b: [f32; 3]) -> f32 {
    (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]
}

/// |v| = √(v · v).
pub fn length3(v: [f32; 3]) -> f32 {
    sqrt(dot3(v, v))
}

/// One of the functions above, as `kernels/gpu/fmath/fmath_eval.comp` numbers them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[allow(missing_docs)] // each is the function of the same name above
pub enum Function {
    Rcp,
    Rcp1To2,
    Div,
    DivRn,
    Sqrt,
    Exp,
    ExpLe0,
    Expm1,
    Log,
    Sigmoid,
    SigmoidGrad,
    Tanh,
    Pow,
    Sin,
    Cos,
    RcpPos,
}

impl Function {
    /// Every function, in the kernel's order.
    pub const ALL: [Function; 16] = [
        Function::Rcp,
        Function::Rcp1To2,
        Function::Div,
        Function::DivRn,
        Function::Sqrt,
        Function::Exp,
        Function::ExpLe0,
        Function::Expm1,
        Function::Log,
        Function::Sigmoid,
        Function::SigmoidGrad,
        Function::Tanh,
        Function::Pow,
        Function::Sin,
        Function::Cos,
        Function::RcpPos,
    ];

    /// Its name, as in `fmath.glsl` without `fm_`.
    pub fn name(self) -> &'static str {
        match self {
            Function::Rcp => "rcp",
            Function::Rcp1To2 => "rcp_1_2",
            Function::Div => "div",
            Function::DivRn => "div_rn",
            Function::Sqrt => "sqrt",
            Function::Exp => "exp",
            Function::ExpLe0 => "exp_le0",
            Function::Expm1 => "expm1",
            Function::Log => "log",
            Function::Sigmoid => "sigmoid",
            Function::SigmoidGrad => "sigmoid_grad",
            Function::Tanh => "tanh",
            Function::Pow => "pow",
            Function::Sin => "sin",
            Function::Cos => "cos",
            Function::RcpPos => "rcp_pos",
        }
    }

    /// Whether `x` is in its domain: the kernel's hot-path variants (`fm_rcp_1_2`, `fm_rcp_pos`,
    /// `fm_exp_le0`) promise the general function's bits on theirs only.
    pub fn domain(self, x: f32) -> bool {
        match self {
            Function::Rcp1To2 => (1.0..=2.0).contains(&x) || x.is_nan(),
            Function::RcpPos => x > 0.0,
            Function::ExpLe0 => x <= 0.0 || x.is_nan(),
            _ => true,
        }
    }

    /// Whether it reads its second argument.
    pub fn binary(self) -> bool {
        matches!(self, Function::Div | Function::DivRn | Function::Pow)
    }

    /// The CPU twin: `f(x, y)` (`y` unused by unary functions).
    pub fn eval(self, x: f32, y: f32) -> f32 {
        match self {
            Function::Rcp | Function::Rcp1To2 | Function::RcpPos => rcp(x),
            Function::Div => div(x, y),
            Function::DivRn => div_rn(x, y),
            Function::Sqrt => sqrt(x),
            Function::Exp | Function::ExpLe0 => exp(x),
            Function::Expm1 => expm1(x),
            Function::Log => log(x),
            Function::Sigmoid => sigmoid(x),
            Function::SigmoidGrad => sigmoid_grad(x),
            Function::Tanh => tanh(x),
            Function::Pow => pow(x, y),
            Function::Sin => sin(x),
            Function::Cos => cos(x),
        }
    }

    /// The f64 function it approximates, for accuracy checks.
    pub fn reference(self, x: f64, y: f64) -> f64 {
        match self {
            Function::Rcp | Function::Rcp1To2 | Function::RcpPos => 1.0 / x,
            Function::Div | Function::DivRn => x / y,
            Function::Sqrt => x.sqrt(),
            Function::Exp | Function::ExpLe0 => x.exp(),
            Function::Expm1 => x.exp_m1(),
            Function::Log => x.ln(),
            Function::Sigmoid => 1.0 / (1.0 + (-x).exp()),
            Function::SigmoidGrad => (-x.abs()).exp() / (1.0 + (-x.abs()).exp()).powi(2),
            Function::Tanh => x.tanh(),
            Function::Pow => x.powf(y),
            Function::Sin => x.sin(),
            Function::Cos => x.cos(),
        }
    }
}

pub use gpu::Eval;

/// The functions on the device.
pub mod gpu {
    use bytemuck::{Pod, Zeroable};
    use std::sync::Arc;

    use super::Function;
    use crate::error::{Error, Result};
    use crate::gpu::{Context, Kernel, specs};

    #[repr(C)]
    #[derive(Clone, Copy, Pod, Zeroable)]
    struct Push {
        n: u32,
        function: u32,
    }

    /// `kernels/gpu/fmath/fmath_eval.comp`: evaluates one function on the device, element by
    /// element, so that a device's results can be compared with the CPU twin's bit for bit
    /// (the check `.ci/gpu-check` runs on a new driver).
    pub struct Eval {
        kernel: Arc<Kernel>,
    }

    impl Eval {
        /// The kernel, made once per context.
        pub fn new(ctx: &Context) -> Result<Self> {
            Ok(Self {
                kernel: ctx.kernel(&specs::FMATH_EVAL, &[])?,
            })
        }

        /// `f(a[i], b[i])` for every i; `b` is empty for a unary function, else as long as `a`.
        pub fn run(
            &self,
            ctx: &Context,
            function: Function,
            a: &[f32],
            b: &[f32],
        ) -> Result<Vec<f32>> {
            if function.binary() == b.is_empty() || (function.binary() && a.len() != b.len()) {
                return Err(Error::Input(format!(
                    "fmath {}: {} first and {} second arguments",
                    function.name(),
                    a.len(),
                    b.len()
                )));
            }
            if a.is_empty() {
                return Ok(Vec::new());
            }
            let n = a.len() as u32;
            let bytes = 4 * u64::from(n);
            let a_buf = ctx.upload_buffer("fmath a", a)?;
            let b_buf = if b.is_empty() {
                ctx.upload_buffer("fmath b", &[0.0f32])?
            } else {
                ctx.upload_buffer("fmath b", b)?
            };
            let out = ctx.create_buffer("fmath out", bytes, crate::gpu::MemoryKind::Device)?;
            let push = Push {
                n,
                function: Function::ALL
                    .iter()
                    .position(|f| *f == function)
                    .unwrap_or(0) as u32,
            };
            ctx.submit_and_wait(|rec| {
                let bindings = specs::FmathEvalBindings {
                    a: a_buf.range(0, bytes),
                    b: b_buf.range(0, b_buf.size()),
                    out: out.range(0, bytes),
                };
                rec.dispatch(
                    &self.kernel,
                    &bindings.for_kernel(&self.kernel)?,
                    &push,
                    n.div_ceil(256),
                )
            })?;
            ctx.read_buffer(&out, 0, a.len())
        }
    }
}
