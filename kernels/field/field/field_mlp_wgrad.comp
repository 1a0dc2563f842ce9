#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
// MLP backward, step 3 of 4: the chunk partials of every parameter. Layer l's parameters as a
// matrix of out_dim rows and in_dim + 1 columns (the weights W_l[o][i], then the bias b_l[o] as
// column in_dim, whose input is 1), cut into tiles of WG_ROWS × WG_COLS; one invocation per
// (chunk of FIELD_CHUNK points, tile):
// partial[chunk · P + j] = Σ over the chunk's points, in order, of δ_l[o] · a_l[i] (weight j =
// W_l[o][i]) or δ_l[o] (bias j = b_l[o]). Per point a tile loads WG_ROWS δs and WG_COLS inputs
// for WG_ROWS · WG_COLS products (one parameter per invocation loaded two values per product:
// on llvmpipe every one of those loads is a per-lane gather). Each parameter's sum runs over the
// same points in the same order as the twin's. Twin: the plain sums of
// `crate::field::cpu::backward`.
#include "common.glsl"

#define FIELD_CHUNK 256u
#define WG_ROWS 8u
#define WG_COLS 8u

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Acts { float acts[]; };
layout(std430, set = 0, binding = 1) readonly buffer Deltas { float deltas[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Partial { float partial[]; };

layout(push_constant) uniform Push {
    vec4 cube;
    uint n;
    uint layers;
    uint width;
    uint freqs;
    float beta;
    uint batch;
    uint chunks;
    uint param_count;
} pc;

// Layer l's (inputs, outputs): the encoding's E = 3 + 6F into the first, W between, 1 out.
uvec2 layer_dims(uint l) {
    return uvec2(l == 0u ? 3u + 6u * pc.freqs : pc.width, l == pc.layers ? 1u : pc.width);
}

uint layer_tiles(uint l) {
    uvec2 d = layer_dims(l);
    return ((d.y + WG_ROWS - 1u) / WG_ROWS) * ((d.x + 1u + WG_COLS - 1u) / WG_COLS);
}

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint tiles = 0u;
    for (uint l = 0u; l <= pc.layers; ++l) {
        tiles += layer_tiles(l);
    }
    uint chunk = id / tiles;
    if (chunk >= pc.chunks) {
        return;
    }
    // The tile's layer, its parameter offset and its first input feature in acts.
    uint t = id % tiles;
    uint l = 0u;
    uint off = 0u;
    for (; t >= layer_tiles(l); ++l) {
        t -= layer_tiles(l);
        uvec2 d = layer_dims(l);
        off += d.y * d.x + d.y;
    }
    uvec2 d = layer_dims(l);
    uint in_dim = d.x;
    uint out_dim = d.y;
    uint feature = l == 0u ? 0u : 3u + 6u * pc.freqs + (l - 1u) * pc.width;
    uint col_tiles = (in_dim + 1u + WG_COLS - 1u) / WG_COLS;
    uint o0 = (t / col_tiles) * WG_ROWS;
    uint c0 = (t % col_tiles) * WG_COLS;
    // Rows and columns past the matrix read a valid row (the last) and are not stored.
    uint delta_row[WG_ROWS];
    [[unroll]] for (uint r = 0u; r < WG_ROWS; ++r) {
        delta_row[r] = (l * pc.width + min(o0 + r, out_dim - 1u)) * pc.batch;
    }
    uint act_row[WG_COLS];
    bool is_bias[WG_COLS];
    [[unroll]] for (uint c = 0u; c < WG_COLS; ++c) {
        is_bias[c] = c0 + c >= in_dim;
        act_row[c] = (feature + min(c0 + c, in_dim - 1u)) * pc.batch;
    }
    float s[WG_ROWS][WG_COLS];
    [[unroll]] for (uint r = 0u; r < WG_ROWS; ++r) {
        [[unroll]] for (uint c = 0u; c < WG_COLS; ++c) {
            s[r][c] = 0.0;
        }
    }
    uint p0 = chunk * FIELD_CHUNK;
    uint p1 = min(p0 + FIELD_CHUNK, pc.n);
    for (uint p = p0; p < p1; ++p) {
        float dl[WG_ROWS];
        [[unroll]] for (uint r = 0u; r < WG_ROWS; ++r) {
            dl[r] = deltas[delta_row[r] + p];
        }
        [[unroll]] for (uint c = 0u; c < WG_COLS; ++c) {
            float a = is_bias[c] ? 1.0 : acts[act_row[c] + p];
            [[unroll]] for (uint r = 0u; r < WG_ROWS; ++r) {
                s[r][c] += dl[r] * a;
            }
        }
    }
    [[unroll]] for (uint r = 0u; r < WG_ROWS; ++r) {
        uint o = o0 + r;
        [[unroll]] for (uint c = 0u; c < WG_COLS; ++c) {
            uint i = c0 + c;
            if (o < out_dim && i <= in_dim) {
                uint j = off + (i == in_dim ? out_dim * in_dim + o : o * in_dim + i);
                partial[chunk * pc.param_count + j] = s[r][c];
            }
        }
    }
}
