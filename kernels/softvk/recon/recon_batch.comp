#version 460
#extension GL_GOOGLE_include_directive : require
// One training batch gathered on the GPU from the views staged for the submission (uint8
// RGBA, [slot][view a, view b][channel][row][column], four bytes per u32 word, little-endian:
// `crate::recon::batch::stage_views`) by the schedule entry (object, view a, view b, slot) of
// each batch slot at iteration `iteration`:
//   input[b]              = views[slot, a] / 255                    (4 × H × W floats)
//   targets[2b + j]       = alpha of views[slot, j] / 255           (H × W floats)
//   target_images[2b + j] = views[slot, j] / 255 as RGBA per pixel (the renderer's
//                           output layout, for the colour loss)
//   rotations[2b + j]     = view_rotations[view j]                  (the turn about y that
//                           brings view j's camera to the scene's one camera)
// One invocation per (slot, pixel). Twin: `crate::recon::batch::cpu::gather`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Views { uint views[]; };
layout(std430, set = 0, binding = 1) readonly buffer Schedule { uvec4 schedule[]; };
layout(std430, set = 0, binding = 2) readonly buffer ViewRotations { vec2 view_rotations[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Input { float input_images[]; };
layout(std430, set = 0, binding = 4) writeonly buffer Targets { float targets[]; };
layout(std430, set = 0, binding = 5) writeonly buffer Rotations { vec2 rotations[]; };
layout(std430, set = 0, binding = 6) writeonly buffer TargetImages { vec4 target_images[]; };

layout(push_constant) uniform Push {
    uint batch;
    uint pixels;      // H × W
    uint views;       // views per object in the dataset (24): the rotation table's length
    uint iteration;   // row of `schedule` (batch entries each)
} pc;

float byte_at(uint index) {
    uint word = views[index >> 2u];
    return float((word >> (8u * (index & 3u))) & 255u) * (1.0 / 255.0);
}

void main() {
    uint gid = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (gid >= pc.batch * pc.pixels) {
        return;
    }
    uint b = gid / pc.pixels;
    uint p = gid - b * pc.pixels;
    uvec4 e = schedule[pc.iteration * pc.batch + b];
    uint view_a = (2u * e.w) * 4u * pc.pixels;
    uint view_b = (2u * e.w + 1u) * 4u * pc.pixels;
    for (uint ch = 0u; ch < 4u; ++ch) {
        input_images[(4u * b + ch) * pc.pixels + p] = byte_at(view_a + ch * pc.pixels + p);
    }
    for (uint j = 0u; j < 2u; ++j) {
        uint view = j == 0u ? view_a : view_b;
        vec4 rgba = vec4(byte_at(view + p), byte_at(view + pc.pixels + p),
                         byte_at(view + 2u * pc.pixels + p), byte_at(view + 3u * pc.pixels + p));
        targets[(2u * b + j) * pc.pixels + p] = rgba.a;
        target_images[(2u * b + j) * pc.pixels + p] = rgba;
    }
    if (p == 0u) {
        rotations[2u * b] = view_rotations[e.y];
        rotations[2u * b + 1u] = view_rotations[e.z];
    }
}
