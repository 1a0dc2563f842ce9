// The colour generator's layout, shared by its five kernels (`crate::recon::colors`). Per object
// b its outputs start at b · stride + offset: P × K sampling logits s[p][k] (palette entry p's
// weight on pooled cell k), then V × P selection logits w[i][p] (vertex i's weight on entry p).
//   q_k = the mean RGB of cell k (pool × pool pixels of the input image; K = grid²)
//   C_p = Σ_k softmax_k(s[p])_k q_k                      (the palette, sampled from the image)
//   c_i = Σ_p softmax_p(w[i])_p C_p                      (the vertex colour, a learned selection)
// The palette keeps in .w the log-normalizer of its softmax, max_k s + log Σ_k e^{s − max}.

layout(push_constant) uniform Push {
    uint vertex_count;  // V
    uint objects;
    uint copies;        // copies of each object the colours are written to
    uint stride;        // network outputs per object
    uint offset;        // the generator's first output in an object's
    uint palette;       // P
    uint grid;          // pooled cells per side (K = grid²)
    uint pool;          // pixels per cell side (the image side is grid · pool)
} pc;

uint sampling_logit(uint b, uint p, uint k) {
    return b * pc.stride + pc.offset + p * pc.grid * pc.grid + k;
}

uint selection_logit(uint b, uint i, uint p) {
    return b * pc.stride + pc.offset + pc.palette * pc.grid * pc.grid + i * pc.palette + p;
}
