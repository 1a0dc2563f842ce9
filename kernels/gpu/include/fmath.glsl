// softvk's own float maths: every function here is a fixed sequence of f32 additions,
// subtractions and multiplications (correctly rounded on every conformant Vulkan device, and never
// fused: build.rs decorates each NoContraction), comparisons, and exact integer bit operations.
// None calls a builtin whose precision Vulkan leaves to the driver (`exp`, `log`, `pow`, division,
// `sqrt`, `inversesqrt`, `sin`, `cos`, `tanh`) or whose summation order it leaves open (`dot`,
// `length`, `normalize`, `cross`, `mix`, matrix products). So each returns the same bits on any
// device, and `src/fmath.rs` is its CPU twin, operation for operation (`tests/fmath.rs` compares
// them bit for bit).
//
// Subnormals: an input below 2^-126 in magnitude is read as a signed zero (or, in fm_div_rn, by
// its bits) and a result that would fall below 2^-126 is returned as zero (exp: below −126 ln 2;
// rcp: from |x| ≥ 2^126), decided by comparisons, so a device that flushes subnormals and one
// that keeps them give the same bits. No intermediate of a normal input is subnormal (range
// reduction keeps them near 1). The arithmetic of the kernels around these functions is not
// guarded so: an intermediate below 2^-126 there may still differ between such devices.
//
// Accuracy, worst measured against f64 by `tests/fmath.rs` (ulps of the result): rcp 1.2, div
// 1.8 (div_rn: correctly rounded), sqrt 0.8, exp 1.0, expm1 1.53, log 0.8, sigmoid 2.9, its
// derivative 5.5, tanh 3.3, pow 27 (exp(y ln x), as Vulkan's own), sin and cos 1.3 · 2^-24
// absolute for |x| ≤ 8192.
#ifndef SOFTVK_FMATH_GLSL
#define SOFTVK_FMATH_GLSL

const float FM_MIN_NORMAL = 1.17549435e-38;  // 2^-126
#define FM_INF uintBitsToFloat(0x7f800000u)
#define FM_NAN uintBitsToFloat(0x7fc00000u)

// 2^k for -126 ≤ k ≤ 127, built from its bits.
float fm_pow2(int k) {
    return uintBitsToFloat(uint(k + 127) << 23);
}

// x, or a zero of x's sign when |x| is below the normal range.
float fm_ftz(float x) {
    return abs(x) < FM_MIN_NORMAL ? uintBitsToFloat(floatBitsToUint(x) & 0x80000000u) : x;
}

// The functions compute their main path for every input and choose the special cases by selects
// at the end (on a SIMD device a branch costs as much as both sides); the main path's operands
// are clamped where a special input would make them meaningless, never where they matter.

// 1 / m for m ∈ [1, 2): Newton's iteration from a linear start, in (0.5, 1].
float fm_rcp_mantissa(float m) {
    float y = 1.4117647 - 0.47058824 * m;  // 24/17 − 8/17 m: |error| ≤ 1/17
    y = y + y * (1.0 - m * y);
    y = y + y * (1.0 - m * y);
    return y + y * (1.0 - m * y);  // |error| ≤ (1/17)^8 before rounding
}

// 1 / x: the mantissa's reciprocal, then the exponent (by the bits: integer operations where a
// multiplication by 2^-e would need the power built).
float fm_rcp(float x) {
    uint bits = floatBitsToUint(x);
    uint mag = bits & 0x7fffffffu;
    float y = fm_rcp_mantissa(uintBitsToFloat((bits & 0x007fffffu) | 0x3f800000u));
    // y ∈ (0.5, 1] times 2^-e, e = the exponent field − 127 ≤ 125 here: normal, so the exact
    // product y · 2^-e, taken by subtracting e from y's exponent field.
    uint sign = bits & 0x80000000u;
    float r = uintBitsToFloat(((floatBitsToUint(y) + 0x3f800000u) - (bits & 0x7f800000u)) | sign);
    // Zero and subnormal: ±inf. From 2^126 (e ≥ 126: |1/x| ≤ 2^-126) and infinite: ±0. NaN.
    return mag < 0x00800000u ? uintBitsToFloat(sign | 0x7f800000u)
         : (mag >= 0x7e800000u ? (mag > 0x7f800000u ? x : uintBitsToFloat(sign)) : r);
}

// fm_rcp(x) for x > 0 (not NaN), its bits without the sign and NaN cases: for the depth's, the
// clip's sum's and the alpha factor's reciprocals, taken at every (pixel, face) pair.
float fm_rcp_pos(float x) {
    uint bits = floatBitsToUint(x);
    float y = fm_rcp_mantissa(uintBitsToFloat((bits & 0x007fffffu) | 0x3f800000u));
    float r = uintBitsToFloat((floatBitsToUint(y) + 0x3f800000u) - (bits & 0x7f800000u));
    return bits < 0x00800000u ? FM_INF : (bits >= 0x7e800000u ? 0.0 : r);
}

// fm_rcp(x) for x ∈ [1, 2] (or NaN), its bits without the exponent and special cases: for the
// sigmoid's 1 / (1 + e), e ∈ [0, 1], taken at every (pixel, face) pair.
float fm_rcp_1_2(float x) {
    bool two = x >= 2.0;
    float y = fm_rcp_mantissa(two ? 1.0 : x);  // the mantissa: 2 is 1 · 2^1
    return two ? y * 0.5 : y;
}

// a / b as a · (1 / b): within 2 ulps; a subnormal a or result reads as zero.
float fm_div(float a, float b) {
    return fm_ftz(fm_ftz(a) * fm_rcp(b));
}

// fm_div(a, b) for b > 0 (not NaN).
float fm_div_pos(float a, float b) {
    return fm_ftz(fm_ftz(a) * fm_rcp_pos(b));
}

// Dekker's exact product: p + e = x y exactly (Veltkamp's split into 12-bit halves), for
// operands whose products and halves stay normal.
void fm_two_product(float x, float y, out float p, out float e) {
    p = x * y;
    float cx = 4097.0 * x;
    float xh = cx - (cx - x);
    float xl = x - xh;
    float cy = 4097.0 * y;
    float yh = cy - (cy - y);
    float yl = y - yh;
    e = ((xh * yh - p) + xh * yl + xl * yh) + xl * yl;
}

// |x| = m · 2^e with m ∈ [1, 2), from the bits (a subnormal's normalised by its leading bit), for
// x finite and nonzero.
float fm_frexp(float x, out int e) {
    uint bits = floatBitsToUint(x) & 0x7fffffffu;
    uint field = bits >> 23;
    uint mant = bits & 0x007fffffu;
    int shift = 23 - findMSB(mant | 1u);
    e = field == 0u ? -126 - shift : int(field) - 127;
    uint m = field == 0u ? (mant << uint(shift)) & 0x007fffffu : mant;
    return uintBitsToFloat(m | 0x3f800000u);
}

// a / b correctly rounded (to nearest, ties to even): IEEE division, for kernels that must equal
// another library's bit for bit (PyTorch3D's rasterizer). Subnormal operands are read by their
// bits, so they count; a quotient below 2^-126 is rounded twice (the last place may differ
// from IEEE at a tie) and is zero on a device that flushes subnormals.
// The mantissas' quotient (both in [1, 2)) from the reciprocal is corrected once by its
// remainder; then its exact remainder A − q B (Dekker's product; A − p is exact by Sterbenz's
// lemma, and the remainder of a faithful quotient is a float) is compared with the half-ulp
// steps on either side, each comparison's sign exact; then the exponent.
float fm_div_rn(float a, float b) {
    int ea;
    int eb;
    float A = fm_frexp(a, ea);
    float B = fm_frexp(b, eb);
    float r = fm_rcp_mantissa(B);  // fm_rcp(B)
    float q = A * r;
    float p;
    float e;
    fm_two_product(q, B, p, e);
    q = q + ((A - p) - e) * r;
    fm_two_product(q, B, p, e);
    float rem = (A - p) - e;
    uint bits = floatBitsToUint(q);
    float up = uintBitsToFloat(bits + 1u);
    float down = uintBitsToFloat(bits - 1u);
    float above = rem - ((up - q) * 0.5) * B;    // (A/B − (q + ulp⁺/2)) B: its sign
    float below = rem + ((q - down) * 0.5) * B;  // (A/B − (q − ulp⁻/2)) B
    bool odd = (bits & 1u) != 0u;
    q = rem > 0.0 ? ((above > 0.0 || (above == 0.0 && odd)) ? up : q)
                  : ((below < 0.0 || (below == 0.0 && odd)) ? down : q);
    // q ∈ [0.5, 2]: scale by 2^k in two steps that keep every product but the last normal:
    // 2^127 then the rest above the normal range, 2^(k + 64) then 2^-64 below it.
    int k = ea - eb;
    int k1 = k > 127 ? 127 : (k >= -126 ? k : max(k + 64, -126));
    int k2 = k > 127 ? min(k - 127, 127) : (k >= -126 ? 0 : -64);
    float y = (q * fm_pow2(k1)) * fm_pow2(k2);
    y = k < -189 ? 0.0 : y;
    // Zeros, infinities and NaN.
    bool a_zero = (floatBitsToUint(a) & 0x7fffffffu) == 0u;
    bool b_zero = (floatBitsToUint(b) & 0x7fffffffu) == 0u;
    bool a_inf = abs(a) == FM_INF;
    bool b_inf = abs(b) == FM_INF;
    y = (a_zero || b_inf) ? 0.0 : ((b_zero || a_inf) ? FM_INF : y);
    y = isnan(a) || isnan(b) || (a_zero && b_zero) || (a_inf && b_inf) ? FM_NAN : y;
    bool negative = (floatBitsToUint(a) ^ floatBitsToUint(b)) >= 0x80000000u;
    return negative ? -y : y;
}

// sqrt(x): an inverse square root by Newton's iteration on m ∈ [1, 4), then one correction.
float fm_sqrt(float x) {
    uint bits = floatBitsToUint(x);
    int e = int((bits >> 23) & 0xffu) - 127;
    int odd = e & 1;  // e = 2 h + odd (two's complement: −3 & 1 = 1)
    float m = uintBitsToFloat((bits & 0x007fffffu) | 0x3f800000u);
    m = odd == 1 ? 2.0 * m : m;  // m ∈ [1, 4)
    float y = 1.0 - 0.15 * m;     // 1 / sqrt(m) within 0.2
    y = y * (1.5 - 0.5 * m * y * y);
    y = y * (1.5 - 0.5 * m * y * y);
    y = y * (1.5 - 0.5 * m * y * y);
    y = y * (1.5 - 0.5 * m * y * y);  // relative error below 2^-28 before rounding
    float s = m * y;
    s = s + 0.5 * y * (m - s * s);
    float r = s * fm_pow2(clamp(e - odd, -126, 126) / 2);
    // Zero, subnormal, negative, NaN, infinite.
    float special = x >= 0.0 || abs(x) < FM_MIN_NORMAL ? (x == FM_INF ? x : 0.0) : FM_NAN;
    return x >= FM_MIN_NORMAL && x != FM_INF ? r : special;
}

// exp(r) − 1 = r + r² P(r) for |r| ≤ ln(2)/2 + a little, P Cephes's minimax (expf).
float fm_expm1_reduced(float r) {
    float p = 1.9875691500e-4;
    p = 1.3981999507e-3 + r * p;
    p = 8.3334519073e-3 + r * p;
    p = 4.1665795894e-2 + r * p;
    p = 1.6666665459e-1 + r * p;
    p = 5.0000001201e-1 + r * p;
    return r + (r * r) * p;
}

// ln 2 in two parts: k · FM_LN2_HI is exact for |k| < 2^9.
const float FM_LN2_HI = 0.693145751953125;     // 0x3f317200
const float FM_LN2_LO = 1.428606765330187e-06; // 0x35bfbe8e
const float FM_LOG2E = 1.44269504;
const float FM_EXP_MAX = 88.7228394;  // above: exp overflows
// The least float whose exp is normal: the float just above −126 ln 2 = −87.3365447...
// (0xc2aeac4f); below it exp(x) < 2^-126, returned as 0. At it k = −126 and r ≥ 0, so the
// result p · 2^-126 has p ≥ 1: normal.
const float FM_EXP_MIN = -87.3365402;

// k = round(x / ln 2) and r = x − k ln 2, for x clamped to [FM_EXP_MIN, FM_EXP_MAX]
// (k ∈ [−126, 128]).
float fm_reduce_ln2(float x, out int k) {
    float kf = floor(clamp(x, FM_EXP_MIN, FM_EXP_MAX) * FM_LOG2E + 0.5);
    k = int(kf);
    return (x - kf * FM_LN2_HI) - kf * FM_LN2_LO;
}

// exp(x): 0 below FM_EXP_MIN (no subnormal results), +inf above ln(FLT_MAX). A subnormal x needs no
// flush: 1 + x and 1 + 0 are both 1.
float fm_exp(float x) {
    int k;
    float p = 1.0 + fm_expm1_reduced(fm_reduce_ln2(x, k));
    // k ∈ [−126, 128]; 2^128 in two factors.
    float y = k > 127 ? (p * 2.0) * fm_pow2(127) : p * fm_pow2(k);
    return isnan(x) ? x : (x > FM_EXP_MAX ? FM_INF : (x < FM_EXP_MIN ? 0.0 : y));
}

// fm_exp(x) for x ≤ 0 (or NaN), its bits without the overflow cases: for the exponents of the
// sigmoid and the softmax, taken at every (pixel, face) pair.
float fm_exp_le0(float x) {
    // fm_reduce_ln2 with x ≤ 0 needs no upper clamp: k ≤ 0.
    float kf = floor(max(x, FM_EXP_MIN) * FM_LOG2E + 0.5);
    float r = (x - kf * FM_LN2_HI) - kf * FM_LN2_LO;
    float p = 1.0 + fm_expm1_reduced(r);
    // p · 2^k by the exponent field: normal (k ≥ −126 and p ≥ 1 at k = −126), so the exact
    // product.
    float y = uintBitsToFloat(floatBitsToUint(p) + uint(int(kf) << 23));
    return isnan(x) ? x : (x < FM_EXP_MIN ? 0.0 : y);
}

// exp(x) − 1, exact near zero (no cancellation).
float fm_expm1(float x) {
    int k;
    float q = fm_expm1_reduced(fm_reduce_ln2(fm_ftz(x), k));
    // 2^k (1 + q) − 1 = (2^k − 1) + 2^k q, each 2^k − 1 exact for −24 ≤ k ≤ 24.
    float t = k > 127 ? 2.0 * fm_pow2(127) : fm_pow2(k);
    float y = k == 0 ? q : (k <= 24 ? (t - 1.0) + t * q : (t + t * q) - 1.0);
    // exp(x) < 2^-24 below −17: −1 after rounding.
    return isnan(x) ? x : (x > FM_EXP_MAX ? FM_INF : (x < -17.0 ? -1.0 : y));
}

// ln(x), after FreeBSD's logf (s = f / (2 + f), a polynomial in s², the exponent in two parts):
// −inf for zero and subnormal inputs, NaN below zero.
const float FM_LOG_LN2_HI = 6.9313812256e-01;  // 0x3f317180
const float FM_LOG_LN2_LO = 9.0580006145e-06;  // 0x3717f7d1
float fm_log(float x) {
    uint bits = floatBitsToUint(x);
    int k = int((bits >> 23) & 0xffu) - 127;
    float m = uintBitsToFloat((bits & 0x007fffffu) | 0x3f800000u);
    bool high = m > 1.41421354;
    m = high ? 0.5 * m : m;
    k = high ? k + 1 : k;
    float f = m - 1.0;  // exact: m ∈ (0.707, 1.415]
    float s = f * fm_rcp(2.0 + f);
    float z = s * s;
    float w = z * z;
    float t1 = w * (0.40000972152 + w * 0.24279078841);
    float t2 = z * (0.66666662693 + w * 0.28498786688);
    float r = t2 + t1;
    float hfsq = 0.5 * f * f;
    float dk = float(k);
    float y = dk * FM_LOG_LN2_HI - ((hfsq - (s * (hfsq + r) + dk * FM_LOG_LN2_LO)) - f);
    float special = isnan(x) || x == FM_INF ? x : (abs(x) < FM_MIN_NORMAL ? -FM_INF : FM_NAN);
    return x >= FM_MIN_NORMAL && x != FM_INF ? y : special;
}

// 1 / (1 + exp(−x)), from e = exp(−|x|) (never overflows): 1 / (1 + e) for x ≥ 0, e / (1 + e)
// below. `fm_sigmoid_grad` shares e and 1 / (1 + e), so a kernel that takes both pays for one
// exp and one reciprocal (the compiler merges the identical operations).
float fm_sigmoid(float x) {
    float e = fm_exp_le0(-abs(x));
    float r = fm_rcp_1_2(1.0 + e);
    return x >= 0.0 ? r : e * r;
}

// sigmoid'(x) = e / (1 + e)² with e = exp(−|x|), without the cancellation of s (1 − s).
float fm_sigmoid_grad(float x) {
    float e = fm_exp_le0(-abs(x));
    float r = fm_rcp_1_2(1.0 + e);
    return e * r * r;
}

// tanh(x) = e / (e + 2) with e = expm1(2|x|), odd; ±1 beyond |x| = 9.
float fm_tanh(float x) {
    float a = abs(x);
    float e = fm_expm1(2.0 * min(a, 9.0));
    float t = a > 9.0 ? 1.0 : fm_div(e, e + 2.0);
    return isnan(x) ? x : (x < 0.0 ? -t : t);
}

// x^y for x ≥ 0 as exp(y ln x); 0^y is 0 for y > 0 (+inf for y < 0), and x^0 is 1.
float fm_pow(float x, float y) {
    float r = fm_exp(y * fm_log(x));
    return y == 0.0 ? 1.0 : (abs(x) < FM_MIN_NORMAL ? (y > 0.0 ? 0.0 : FM_INF) : r);
}

// sin and cos of x: j = round(2x / π) and r = x − j π/2 in three parts (each product exact for
// |j| < 2^13, so accurate to |x| ≈ 12 800; beyond, the same bits everywhere, less accurate), then
// Cephes's polynomials on |r| ≤ π/4.
const float FM_PIO2_1 = 1.5703125;                // 0x3fc90000
const float FM_PIO2_2 = 4.837512969970703125e-4;  // 0x39fda000
const float FM_PIO2_3 = 7.54978995489188216e-8;   // 0x33a22169
vec2 fm_sincos(float x) {
    float a = fm_ftz(x);
    float jf = floor(a * 0.636619772 + 0.5);
    float r = ((a - jf * FM_PIO2_1) - jf * FM_PIO2_2) - jf * FM_PIO2_3;
    float z = r * r;
    float s = ((-1.9515295891e-4 * z + 8.3321608736e-3) * z - 1.6666654611e-1) * z * r + r;
    float c = ((2.443315711809948e-5 * z - 1.388731625493765e-3) * z + 4.166664568298827e-2) * z * z
        - 0.5 * z + 1.0;
    // Beyond 2^24 every float is even and the quadrant meaningless: take 0 (still one answer).
    uint q = abs(jf) < 16777216.0 ? uint(int(jf) & 3) : 0u;
    float sn = (q & 1u) == 0u ? s : c;
    float cs = (q & 1u) == 0u ? c : s;
    sn = (q & 2u) == 0u ? sn : -sn;
    cs = ((q + 1u) & 2u) == 0u ? cs : -cs;
    bool finite = !isnan(x) && abs(x) != FM_INF;
    return finite ? vec2(sn, cs) : vec2(FM_NAN);
}
float fm_sin(float x) {
    return fm_sincos(x).x;
}
float fm_cos(float x) {
    return fm_sincos(x).y;
}

// Component by component.
vec2 fm_div2(vec2 a, float b) {
    return vec2(fm_div(a.x, b), fm_div(a.y, b));
}
vec3 fm_div3(vec3 a, float b) {
    return vec3(fm_div(a.x, b), fm_div(a.y, b), fm_div(a.z, b));
}
vec4 fm_div4(vec4 a, float b) {
    return vec4(fm_div(a.x, b), fm_div(a.y, b), fm_div(a.z, b), fm_div(a.w, b));
}
vec3 fm_div_rn3(vec3 a, float b) {
    return vec3(fm_div_rn(a.x, b), fm_div_rn(a.y, b), fm_div_rn(a.z, b));
}
vec4 fm_div4v(vec4 a, vec4 b) {
    return vec4(fm_div(a.x, b.x), fm_div(a.y, b.y), fm_div(a.z, b.z), fm_div(a.w, b.w));
}
vec4 fm_sqrt4(vec4 x) {
    return vec4(fm_sqrt(x.x), fm_sqrt(x.y), fm_sqrt(x.z), fm_sqrt(x.w));
}

// Fixed-order vector maths: ((x + y) + z).
float fm_dot3(vec3 a, vec3 b) {
    return (a.x * b.x + a.y * b.y) + a.z * b.z;
}
float fm_dot2(vec2 a, vec2 b) {
    return a.x * b.x + a.y * b.y;
}
// ((x + y) + z) + w.
float fm_dot4(vec4 a, vec4 b) {
    return ((a.x * b.x + a.y * b.y) + a.z * b.z) + a.w * b.w;
}
vec3 fm_cross(vec3 a, vec3 b) {
    return vec3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
float fm_length3(vec3 v) {
    return fm_sqrt(fm_dot3(v, v));
}
float fm_length2(vec2 v) {
    return fm_sqrt(fm_dot2(v, v));
}
// M v for a column-major 3 × 3 matrix: columns added in order.
vec3 fm_mul33(mat3 m, vec3 v) {
    return (m[0] * v.x + m[1] * v.y) + m[2] * v.z;
}
// M N, column by column.
mat3 fm_mul33m(mat3 m, mat3 n) {
    return mat3(fm_mul33(m, n[0]), fm_mul33(m, n[1]), fm_mul33(m, n[2]));
}

#endif
