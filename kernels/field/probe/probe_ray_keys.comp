#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, backward, step 1: every ray's tile as a sort key (the binning's view-major tile
// index) with the ray's index as the value. A stable sort then lists each tile's rays in ray
// order, and the binning's ranges pass gives each tile its run. Twin: `ray_tile` in
// `probe::prober::cpu`.
#include "common.glsl"
#include "probe.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Values { uint values[]; };

layout(push_constant) uniform Push {
    uint rays;
    uint width;
    uint height;
    uint tile_size;
    uint tiles_x;
    uint tiles_y;
    uint pad0;
    uint pad1;
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.rays) {
        return;
    }
    keys[id] = uvec2(ray_tile(rays[id], pc.width, pc.height, pc.tile_size, pc.tiles_x, pc.tiles_y),
                     0u);
    values[id] = id;
}
