// The MLP field: f(p) = MLP(enc(u)), u = (p − c) / h the point normalised to the cube,
// enc(u) = (u, sin(2^k π u), cos(2^k π u) for k < F) with the sin and cos of each k as
// (sin x, sin y, sin z, cos x, cos y, cos z): E = 3 + 6 F inputs. L hidden layers of W units with
// softplus_β(z) = max(z, 0) + log(1 + exp(−β |z|)) / β, then a linear output. Parameters, layer by
// layer (L hidden, then the output): weights row-major [out][in], then biases [out].
//
// The includer declares `params[]` and a push-constant block `pc` with cube, layers, width,
// freqs, beta (and, with MLP_SAVE, batch), and with MLP_SAVE the buffers `acts[]` and `deltas[]`
// (feature-major: feature f of point i at f * pc.batch + i). Twin: `crate::field::cpu` (Mlp).
#ifndef SOFTVK_FIELD_MLP_GLSL
#define SOFTVK_FIELD_MLP_GLSL

#define MLP_MAX_WIDTH 256u
#define MLP_PI 3.14159265358979

// Ping-pong activations of one invocation: halves [0, MAX) and [MAX, 2 MAX).
float mlp_act[2u * MLP_MAX_WIDTH];

uint mlp_inputs() {
    return 3u + 6u * pc.freqs;
}

// Parameter offset of layer l (0 ≤ l ≤ L; layer L is the output).
uint mlp_layer_offset(uint l) {
    uint e = mlp_inputs();
    uint w = pc.width;
    return l == 0u ? 0u : w * e + w + (l - 1u) * (w * w + w);
}

float mlp_softplus(float z) {
    return max(z, 0.0) + log(1.0 + exp(-pc.beta * abs(z))) / pc.beta;
}

// d softplus_β / dz = sigmoid(β z).
float mlp_softplus_grad(float z) {
    return field_sigmoid(pc.beta * z);
}

// Σ_i params[row + i] · mlp_act[src + i], i < n, four terms per iteration.
float mlp_dot(uint row, uint src, uint n) {
    float s = 0.0;
    uint i = 0u;
    for (; i + 4u <= n; i += 4u) {
        s += params[row + i] * mlp_act[src + i] + params[row + i + 1u] * mlp_act[src + i + 1u]
           + params[row + i + 2u] * mlp_act[src + i + 2u] + params[row + i + 3u] * mlp_act[src + i + 3u];
    }
    for (; i < n; ++i) {
        s += params[row + i] * mlp_act[src + i];
    }
    return s;
}

// The logit at p. With MLP_SAVE, also stores every layer's input (acts: the encoding, then each
// hidden layer's output) and softplus'(z) of every hidden unit (deltas, overwritten later by the
// backward) for point `point`.
float mlp_forward(vec3 p, uint point) {
    vec3 u = field_normalize(p, pc.cube);
    uint e = mlp_inputs();
    mlp_act[0] = u.x;
    mlp_act[1] = u.y;
    mlp_act[2] = u.z;
    float freq = MLP_PI;
    for (uint k = 0u; k < pc.freqs; ++k) {
        vec3 s = sin(freq * u);
        vec3 c = cos(freq * u);
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
    for (uint i = 0u; i < e; ++i) {
        acts[i * pc.batch + point] = mlp_act[i];
    }
#endif
    uint w = pc.width;
    uint in_dim = e;
    uint src = 0u;
    uint off = 0u;
    for (uint l = 0u; l < pc.layers; ++l) {
        uint dst = MLP_MAX_WIDTH - src;
        for (uint o = 0u; o < w; ++o) {
            float z = mlp_dot(off + o * in_dim, src, in_dim) + params[off + w * in_dim + o];
            float a = mlp_softplus(z);
            mlp_act[dst + o] = a;
#ifdef MLP_SAVE
            acts[(e + l * w + o) * pc.batch + point] = a;
            deltas[(l * w + o) * pc.batch + point] = mlp_softplus_grad(z);
#endif
        }
        off += w * in_dim + w;
        in_dim = w;
        src = dst;
    }
    return mlp_dot(off, src, w) + params[off + w];
}

#endif
