// The application's pass after softvk: reads softvk's silhouettes (RGBA per pixel; alpha is the
// silhouette) and its dL/d(vertex positions) from the application's buffers, and writes what it
// read (alpha, then the gradients) doubled into one buffer for read-back. Mirrored by
// `cpu::consume`.

struct Params {
    n: u32,
    frame: u32,
    pixels: u32,
    grads: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> image: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> d_positions: array<f32>;
@group(0) @binding(3) var<storage, read_write> consumed: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i < params.pixels {
        consumed[i] = 2.0 * image[i].w;
    } else if i < params.pixels + params.grads {
        consumed[i] = 2.0 * d_positions[i - params.pixels];
    }
}
