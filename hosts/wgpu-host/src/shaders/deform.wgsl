// The application's "deform the vertices" compute pass, before softvk: scales and moves the rest
// mesh, differently every frame, into the vertex buffer softvk renders (x, y, z, 1 per vertex).
// Mirrored by `cpu::deform`.

struct Params {
    n: u32,
    frame: u32,
    pixels: u32,
    grads: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> rest: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> vertices: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n {
        return;
    }
    let f = f32(params.frame % 4u);
    let scale = vec3<f32>(0.8 + 0.1 * f, 0.9, 0.85 - 0.05 * f);
    let shift = vec3<f32>(0.04 * f, -0.03 * f, 0.0);
    vertices[i] = vec4<f32>(rest[i].xyz * scale + shift, 1.0);
}
