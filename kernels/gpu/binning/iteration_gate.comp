#version 460
#extension GL_GOOGLE_include_directive : require
// The gate of a guarded fitting iteration (`fit::gate`): after the binning's count, decides
// whether the rest of the iteration runs, and writes the indirect grids of the rest's dispatches
// (`Recorder::gated`): their recorded grids when it runs, [0, 0, 0] (nothing) when it does not.
// It does not run when the count's total exceeds the entry capacity, nor after an iteration of
// the same submission did not (the stop is sticky). The first stop records its iteration and
// total. One workgroup. Twin: `fit::gate::cpu::gate`.
#include "common.glsl"

layout(local_size_x = 64) in;

// The binning count's total (one uint).
layout(std430, set = 0, binding = 0) readonly buffer Total { uint total[]; };
// [stopped, iteration of the first stop, its total, total of the last iteration that ran].
layout(std430, set = 0, binding = 1) buffer Status { uint status[]; };
// The recorded grids, 3 words per gated dispatch.
layout(std430, set = 0, binding = 2) readonly buffer Grids { uint grids[]; };
// The grids the gated dispatches read.
layout(std430, set = 0, binding = 3) writeonly buffer Args { uint args[]; };

layout(push_constant) uniform Push {
    uint iteration;
    uint capacity;  // entries the bins hold
    uint words;     // words of grids to copy
    uint pad;
} pc;

shared uint s_run;

void main() {
    uint lid = gl_LocalInvocationIndex;
    if (lid == 0u) {
        uint t = total[0];
        bool stopped = status[0] != 0u;
        bool fits = t <= pc.capacity;
        if (!stopped && !fits) {
            status[0] = 1u;
            status[1] = pc.iteration;
            status[2] = t;
        }
        if (!stopped && fits) {
            status[3] = t;
        }
        s_run = (!stopped && fits) ? 1u : 0u;
    }
    barrier();
    bool run = s_run != 0u;
    for (uint i = lid; i < pc.words; i += 64u) {
        args[i] = run ? grids[i] : 0u;
    }
}
