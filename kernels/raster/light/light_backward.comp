#version 460
#extension GL_GOOGLE_include_directive : require
// The lighting's backward (`reference_grad::lighting_grad_surface` / `lighting_grad_vertex`):
// from dL/d(lit colour) to dL/d(unlit colour) and, through the normals, dL/d(world position)
// per (face, corner) slot, which `light_gather.comp` then adds to each vertex's gradient.
// Surface, one phase, one invocation per face. Vertex, phase 0 per vertex (dL/d(normal sum)),
// phase 1 per face (its three vertices' sums' share of its raw normal). One writer per value.
#include "common.glsl"
#include "light_io.glsl"

layout(local_size_x = 64) in;

// dL/d(lit colour), xyz per colour (the backward's colour gradients).
layout(std430, set = 0, binding = 5) readonly buffer DLit { float d_lit[]; };
// dL/d(unlit colour), xyz per colour.
layout(std430, set = 0, binding = 6) writeonly buffer DBase { float d_base[]; };
// Vertex mode: dL/d(normal sum) per vertex of each mesh.
layout(std430, set = 0, binding = 7) buffer DSums { vec4 d_sums[]; };
// dL/d(world position) per (mesh, face, corner) slot.
layout(std430, set = 0, binding = 8) writeonly buffer Corners { vec4 corners[]; };

vec3 d_lit_at(uint i) {
    return vec3(d_lit[3u * i], d_lit[3u * i + 1u], d_lit[3u * i + 2u]);
}

void write_d_base(uint i, vec3 g) {
    d_base[3u * i] = g.x;
    d_base[3u * i + 1u] = g.y;
    d_base[3u * i + 2u] = g.z;
}

// `face_normal_raw_grad`: the corners' share of dL/d(raw normal) `g` of face f.
void write_corners(uint mesh, uint f, vec3 g) {
    vec3 p0 = world_position(mesh, faces[3u * f]);
    vec3 p1 = world_position(mesh, faces[3u * f + 1u]);
    vec3 p2 = world_position(mesh, faces[3u * f + 2u]);
    vec3 a = p2 - p1;
    vec3 b = p0 - p1;
    vec3 g_a = fm_cross(b, g);
    vec3 g_b = fm_cross(g, a);
    uint slot = 3u * (mesh * pc.face_count + f);
    corners[slot] = vec4(g_b, 0.0);
    corners[slot + 1u] = vec4(-g_a - g_b, 0.0);
    corners[slot + 2u] = vec4(g_a, 0.0);
}

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (pc.vertex_mode != 0u && pc.phase == 0u) {
        if (id >= pc.vertex_count * pc.mesh_count) {
            return;
        }
        uint mesh = id / pc.vertex_count;
        uint v = id - mesh * pc.vertex_count;
        vec3 sum = vertex_normal_sum(mesh, v);
        vec3 n = normalize_eps(sum);
        vec3 d = d_lit_at(id);
        write_d_base(id, d * light_factor(n, pc.directionals));
        vec3 d_light = d * base[id].rgb;
        d_sums[id] = vec4(normalize_eps_grad(sum, light_factor_grad(n, d_light, pc.directionals)),
                          0.0);
        return;
    }
    if (id >= pc.face_count * pc.mesh_count) {
        return;
    }
    uint mesh = id / pc.face_count;
    uint f = id - mesh * pc.face_count;
    if (pc.vertex_mode != 0u) {
        uint v0 = mesh * pc.vertex_count;
        vec3 d_raw = d_sums[v0 + faces[3u * f]].xyz + d_sums[v0 + faces[3u * f + 1u]].xyz
                   + d_sums[v0 + faces[3u * f + 2u]].xyz;
        write_corners(mesh, f, d_raw);
        return;
    }
    vec3 raw = raw_normal(mesh, f);
    vec3 n = normalize_eps(raw);
    vec3 l = light_factor(n, pc.directionals);
    vec3 d_light = vec3(0.0);
    for (uint t = id * pc.texels; t < (id + 1u) * pc.texels; ++t) {
        vec3 d = d_lit_at(t);
        write_d_base(t, d * l);
        d_light += d * base[t].rgb;
    }
    write_corners(mesh, f, normalize_eps_grad(raw, light_factor_grad(n, d_light, pc.directionals)));
}
