// The application's "deform the vertices" compute pass, before softvk: writes one u32 per
// vertex, different every frame. Mirrored by `cpu::deform`.

struct Params {
    n: u32,
    frame: u32,
    rows: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> deformed: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n {
        return;
    }
    // Runtime u32 arithmetic wraps in WGSL, as wrapping_mul does on the CPU.
    deformed[i] = ((i * 2654435761u) ^ (params.frame * 2654435769u)) >> 20u;
}
