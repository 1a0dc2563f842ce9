#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
// `nn_conv_dinput.comp` for output rows of whole texels (out_w a multiple of 4, the gradient at
// a texel boundary), its kernel size, stride and padding specialization constants: per output
// channel and kernel row, the window of gradient texels a block of 4 S input columns gathers
// from and the 4 input channels' weights of each tap (packed by `nn_conv_pack_weights.comp`,
// BY_INPUT) are read as texels of 4 floats, one gather each where a storage-buffer load is a
// scalar loop over the lanes on a CPU device. With K, S, P constant, which taps reach which
// column and where in the window its output sits are constants once the loops over them are
// unrolled (forced: the 4 S × K body is past gallivm's own limit), so the arrays stay in
// registers rather than scratch.
// d_in[b][c][iy][ix] = Σ w[o][c][ky][kx] · d_pre[b][o][oy][ox] over oy·s + ky − p = iy and
// ox·s + kx − p = ix inside the output, in the order o, ky, kx; outputs outside add an exact 0.
// One invocation per block of 4 input channels × 4 S columns of one input row.
// Twin: the d_input loops of `crate::nn::cpu::conv2d_backward`.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(constant_id = 2) const uint K = 5u;
layout(constant_id = 3) const uint S = 2u;
layout(constant_id = 4) const uint P = 2u;

// Input columns 4 S xb + u, u < 4 S, gather from output columns 4 xb + m, m in [M0, M1]
// (M0 = ceil((P + 1 − K) / S), of either sign: the padding may pass the kernel); those lie in
// gradient texels xb + TB .. xb + TB + DT − 1 (TB = floor(M0 / 4)).
const int LOW = int(P) + 1 - int(K);
const int M0 = LOW >= 0 ? (LOW + int(S) - 1) / int(S) : -((-LOW) / int(S));
const int M1 = int((4u * S - 1u + P) / S);
const int TB = M0 >= 0 ? M0 / 4 : -((3 - M0) / 4);
const uint DT = uint(M1 / 4 - TB + 1);
const uint U = 4u * S;

// The packed weights: the 4 input channels of block cb at tap (o, ky, kx), texel
// ((o K + ky) K + kx) CB + cb.
layout(set = 0, binding = 0, rgba32ui) uniform readonly restrict uimageBuffer weights;
// dL/d(pre-activation), d_pre[b][o][oy][ox] at texel ((b O + o) OH + oy) OW / 4 + ox / 4.
layout(set = 0, binding = 1, rgba32ui) uniform readonly restrict uimageBuffer d_pre;
layout(std430, set = 0, binding = 2) writeonly buffer DInput { float d_in[]; };

NN_CONV_PUSH

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.total) {
        return;
    }
    uint x_blocks = (pc.in_w + U - 1u) / U;
    uint c_blocks = (pc.in_c + 3u) / 4u;
    uint xb = id % x_blocks;
    uint t = id / x_blocks;
    uint iy = t % pc.in_h;
    t /= pc.in_h;
    uint cb = t % c_blocks;
    uint b = t / c_blocks;
    // ky ≡ iy + p (mod s) with 0 ≤ oy = (iy + p − ky) / s < out_h: ky from ky0 to below ky1,
    // step s (the lower bound keeps the residue: (out_h − 1) s ≡ 0).
    uint ny = iy + P;
    uint span_y = (pc.out_h - 1u) * S;
    uint ky0 = ny > span_y ? ny - span_y : ny % S;
    uint ky1 = min(K, ny + 1u);
    int row_texels = int(pc.out_w / 4u);
    vec4 acc[U];
    [[unroll]] for (uint u = 0u; u < U; ++u) {
        acc[u] = vec4(0.0);
    }
    for (uint o = 0u; o < pc.out_c; ++o) {
        uint d_plane = (b * pc.out_c + o) * pc.out_h;
        for (uint ky = ky0; ky < ky1; ky += S) {
            int row = int(d_plane + (ny - ky) / S) * row_texels;
            vec4 win[DT];
            [[unroll]] for (uint j = 0u; j < DT; ++j) {
                int tx = int(xb) + TB + int(j);
                bool inside = tx >= 0 && tx < row_texels;
                vec4 v = uintBitsToFloat(imageLoad(d_pre, row + clamp(tx, 0, row_texels - 1)));
                win[j] = inside ? v : vec4(0.0);
            }
            uint w_at = ((o * K + ky) * K) * c_blocks + cb;
            [[unroll]] for (uint kx = 0u; kx < K; ++kx) {
                vec4 w = uintBitsToFloat(imageLoad(weights, int(w_at + kx * c_blocks)));
                [[unroll]] for (uint u = 0u; u < U; ++u) {
                    int n = int(u + P) - int(kx);
                    if (n % int(S) == 0) {
                        // Output column 4 xb + m, m = n / S, at window column m − 4 TB.
                        int at = n / int(S) - 4 * TB;
                        acc[u] += w * win[at / 4][at % 4];
                    }
                }
            }
        }
    }
    for (uint q = 0u; q < 4u; ++q) {
        if (4u * cb + q >= pc.in_c) {
            break;
        }
        uint in_row = ((b * pc.in_c + 4u * cb + q) * pc.in_h + iy) * pc.in_w;
        [[unroll]] for (uint u = 0u; u < U; ++u) {
            uint ix = U * xb + u;
            if (ix < pc.in_w) {
                d_in[in_row + ix] = acc[u][q];
            }
        }
    }
}
