#version 460
#extension GL_GOOGLE_include_directive : require
// The colour generator's pooled input: per object b and cell k = (gy, gx) of the grid, the mean
// RGB of the pool × pool pixels of the input image (4 × H × W floats per object, planar RGBA)
// that the cell covers, summed row by row: pooled[b K + k] = (rgb, 0).
// Twin: `crate::recon::colors::cpu::forward`.
#include "common.glsl"
#include "recon_colors.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Images { float images[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Pooled { vec4 pooled[]; };

void main() {
    uint cells = pc.grid * pc.grid;
    uint gid = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (gid >= pc.objects * cells) {
        return;
    }
    uint b = gid / cells;
    uint k = gid - b * cells;
    uint gy = k / pc.grid;
    uint gx = k - gy * pc.grid;
    uint side = pc.grid * pc.pool;
    uint plane = side * side;
    vec3 sum = vec3(0.0);
    for (uint dy = 0u; dy < pc.pool; ++dy) {
        uint row = (gy * pc.pool + dy) * side + gx * pc.pool;
        for (uint dx = 0u; dx < pc.pool; ++dx) {
            uint p = row + dx;
            sum += vec3(images[4u * b * plane + p], images[(4u * b + 1u) * plane + p],
                        images[(4u * b + 2u) * plane + p]);
        }
    }
    pooled[gid] = vec4(fm_div3(sum, float(pc.pool * pc.pool)), 0.0);
}
