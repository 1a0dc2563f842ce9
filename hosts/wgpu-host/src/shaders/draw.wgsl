// The application's render pass after softvk: draws one point per vertex, reading the deformed
// data and softvk's output as vertex attributes (the vertex-input stage, which softvk's own
// compute-to-compute barriers do not cover), into an R32Uint image of `WIDTH` columns, one pixel
// per vertex in row-major order. Mirrored by `cpu::consume`.

const WIDTH: u32 = 128u;

struct Params {
    n: u32,
    frame: u32,
    rows: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> params: Params;

struct Point {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) value: u32,
}

@vertex
fn vs(
    @builtin(vertex_index) i: u32,
    @location(0) deformed: u32,
    @location(1) scanned: u32,
) -> Point {
    // The centre of pixel (i % WIDTH, i / WIDTH); a point of size 1 covers exactly that pixel.
    let pixel = vec2<f32>(f32(i % WIDTH) + 0.5, f32(i / WIDTH) + 0.5);
    let size = vec2<f32>(f32(WIDTH), f32(params.rows));
    var out: Point;
    out.position = vec4<f32>(pixel.x / size.x * 2.0 - 1.0, 1.0 - pixel.y / size.y * 2.0, 0.0, 1.0);
    out.value = 2u * scanned + deformed;
    return out;
}

@fragment
fn fs(point: Point) -> @location(0) u32 {
    return point.value;
}
