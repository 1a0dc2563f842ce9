// The MLP field: f(p) = MLP(enc(u)), u = (p − c) / h the point normalised to the cube,
// enc(u) = (u, sin(2^k π u), cos(2^k π u) for k < F) with the sin and cos of each k as
// (sin x, sin y, sin z, cos x, cos y, cos z): E = 3 + 6 F inputs. L hidden layers of W units with
// softplus_β(z) = max(z, 0) + log(1 + exp(−β |z|)) / β, then a linear output. Parameters, layer by
// layer (L hidden, then the output): weights row-major [out][in], then biases [out].
//
// The includer declares `params[]` and a push-constant block `pc` with cube, layers, width,
// freqs (read from the specialization constants of field_mlp_shape.glsl instead), beta (and, with
// MLP_SAVE, batch), and with MLP_SAVE the buffers `acts[]` and `deltas[]`
// (feature-major: feature f of point i at f * pc.batch + i). Twin: `crate::field::cpu` (Mlp).
#ifndef SOFTVK_FIELD_MLP_GLSL
#define SOFTVK_FIELD_MLP_GLSL
#extension GL_EXT_control_flow_attributes : require

#define MLP_PI 3.14159265358979
// With MLP_SAVE, the `point` of a lane that stores nothing (one past the end of the batch).
#define MLP_NO_POINT 0xFFFFFFFFu

#include "field_mlp_shape.glsl"

// Ping-pong activations of one invocation: halves [0, HALF) and [HALF, 2 HALF).
float mlp_act[2u * MLP_HALF];

float mlp_softplus(float z) {
    return max(z, 0.0) + fm_div(fm_log(1.0 + fm_exp(-pc.beta * abs(z))), pc.beta);
}

// d softplus_β / dz = sigmoid(β z).
float mlp_softplus_grad(float z) {
    return field_sigmoid(pc.beta * z);
}

// Four terms of mlp_dot.
float mlp_dot4(uint row, uint src) {
    return params[row] * mlp_act[src] + params[row + 1u] * mlp_act[src + 1u]
         + params[row + 2u] * mlp_act[src + 2u] + params[row + 3u] * mlp_act[src + 3u];
}

// Σ_i params[row + i] · mlp_act[src + i], i < n, four terms per iteration.
float mlp_dot(uint row, uint src, uint n) {
    float s = 0.0;
    uint i = 0u;
    if (MLP_UNROLL) {
        [[unroll]] for (; i + 4u <= n; i += 4u) {
            s += mlp_dot4(row + i, src + i);
        }
        [[unroll]] for (; i < n; ++i) {
            s += params[row + i] * mlp_act[src + i];
        }
    } else {
        for (; i + 4u <= n; i += 4u) {
            s += mlp_dot4(row + i, src + i);
        }
        for (; i < n; ++i) {
            s += params[row + i] * mlp_act[src + i];
        }
    }
    return s;
}

// Hidden layer l (its parameters at `off`): mlp_act[dst + o] = softplus(W a + b)[o] from the
// `in_dim` inputs at mlp_act[src ..]; with MLP_SAVE, its outputs into acts and softplus'(z) into
// deltas for point `point`.
void mlp_unit(uint l, uint off, uint src, uint dst, uint in_dim, uint o, uint point) {
    uint w = MLP_WIDTH;
    float z = mlp_dot(off + o * in_dim, src, in_dim) + params[off + w * in_dim + o];
    float a = mlp_softplus(z);
    mlp_act[dst + o] = a;
#ifdef MLP_SAVE
    if (point != MLP_NO_POINT) {
        acts[(mlp_inputs() + l * w + o) * pc.batch + point] = a;
        deltas[(l * w + o) * pc.batch + point] = mlp_softplus_grad(z);
    }
#endif
}

void mlp_layer(uint l, uint off, uint src, uint dst, uint in_dim, uint point) {
    if (MLP_UNROLL) {
        [[unroll]] for (uint o = 0u; o < MLP_WIDTH; ++o) {
            mlp_unit(l, off, src, dst, in_dim, o, point);
        }
    } else {
        [[dont_unroll]] for (uint o = 0u; o < MLP_WIDTH; ++o) {
            mlp_unit(l, off, src, dst, in_dim, o, point);
        }
    }
}

// The logit at p. With MLP_SAVE, also stores every layer's input (acts: the encoding, then each
// hidden layer's output) and softplus'(z) of every hidden unit (deltas, overwritten later by the
// backward) for point `point` (nothing for MLP_NO_POINT).
float mlp_forward(vec3 p, uint point) {
    vec3 u = field_normalize(p, pc.cube);
    uint e = mlp_inputs();
    mlp_act[0] = u.x;
    mlp_act[1] = u.y;
    mlp_act[2] = u.z;
    float freq = MLP_PI;
    [[unroll]] for (uint k = 0u; k < MLP_FREQS; ++k) {
        vec2 sc_x = fm_sincos(freq * u.x);
        vec2 sc_y = fm_sincos(freq * u.y);
        vec2 sc_z = fm_sincos(freq * u.z);
        vec3 s = vec3(sc_x.x, sc_y.x, sc_z.x);
        vec3 c = vec3(sc_x.y, sc_y.y, sc_z.y);
        uint b = 3u + 6u * k;
        mlp_act[b] = s.x;
        mlp_act[b + 1u] = s.y;
        mlp_act[b + 2u] = s.z;
        mlp_act[b + 3u] = c.x;
        mlp_act[b + 4u] = c.y;
        mlp_act[b + 5u] = c.z;
        freq *= 2.0;
    }
#ifdef MLP_SAVE
    if (point != MLP_NO_POINT) {
        for (uint i = 0u; i < e; ++i) {
            acts[i * pc.batch + point] = mlp_act[i];
        }
    }
#endif
    mlp_layer(0u, 0u, 0u, MLP_HALF, e, point);
    // The hidden layers after the first: every trip count below is a constant, so the compiler
    // can unroll them all and keep `mlp_act` in registers (on llvmpipe, an array indexed at run
    // time is scratch memory, read lane by lane).
    if (MLP_UNROLL) {
        [[unroll]] for (uint l = 1u; l < MLP_LAYERS; ++l) {
            uint src = (l & 1u) == 1u ? MLP_HALF : 0u; // layer l − 1 wrote there
            mlp_layer(l, mlp_layer_offset(l), src, MLP_HALF - src, MLP_WIDTH, point);
        }
    } else {
        [[dont_unroll]] for (uint l = 1u; l < MLP_LAYERS; ++l) {
            uint src = (l & 1u) == 1u ? MLP_HALF : 0u;
            mlp_layer(l, mlp_layer_offset(l), src, MLP_HALF - src, MLP_WIDTH, point);
        }
    }
    uint last = (MLP_LAYERS & 1u) == 0u ? 0u : MLP_HALF;
    uint off = mlp_layer_offset(MLP_LAYERS);
    return mlp_dot(off, last, MLP_WIDTH) + params[off + MLP_WIDTH];
}

#endif
