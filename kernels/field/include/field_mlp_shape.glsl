// The MLP field's shape (see field_mlp.glsl) as specialization constants, and its parameter
// layout: layer by layer (L hidden, then the output), weights row-major [out][in], then biases.
#ifndef SOFTVK_FIELD_MLP_SHAPE_GLSL
#define SOFTVK_FIELD_MLP_SHAPE_GLSL

// The shape as specialization constants (the push constants' layers, width and freqs are not
// read; the host specializes every pipeline for its layout). MLP_HALF ≥ max(inputs, width).
// MLP_UNROLL (the host sets it for small networks, `MlpLayout::constants`): every layer and
// unit loop unrolled, so that `mlp_act` is only ever indexed by constants and lives in
// registers. On llvmpipe an array indexed at run time is scratch memory, read and written lane
// by lane: unrolled, a 3 × 32 network evaluates 13× faster (BENCHMARKS.md). Large networks keep the loops
// (unrolled, their code takes minutes to compile).
layout(constant_id = 0) const uint MLP_LAYERS = 1u;
layout(constant_id = 1) const uint MLP_WIDTH = 1u;
layout(constant_id = 2) const uint MLP_FREQS = 0u;
layout(constant_id = 3) const uint MLP_HALF = 256u;
layout(constant_id = 4) const bool MLP_UNROLL = false;

uint mlp_inputs() {
    return 3u + 6u * MLP_FREQS;
}

// Parameter offset of layer l (0 ≤ l ≤ L; layer L is the output).
uint mlp_layer_offset(uint l) {
    uint e = mlp_inputs();
    uint w = MLP_WIDTH;
    return l == 0u ? 0u : w * e + w + (l - 1u) * (w * w + w);
}

#endif
