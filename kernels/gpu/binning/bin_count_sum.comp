#version 460
#extension GL_GOOGLE_include_directive : require
// Binning, the exact total of a count pass whose u32 scan could wrap (items × tiles past 2^32,
// `Binner::record_count`): invocation i adds the counts of items [i S, (i + 1) S) into a 64-bit
// sum (two words with a carry; S = `per_sum`) and writes it; the host adds these few sums
// (`Bins::read_total`). So a binning is refused only when its real entries do not fit, never
// on a worst-case bound. One loop of at most S iterations per invocation.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Counts { uint counts[]; };
// (low, high) words of each range's sum.
layout(std430, set = 0, binding = 1) writeonly buffer Sums { uvec2 sums[]; };

layout(push_constant) uniform Push {
    uint n;       // counts
    uint per_sum; // counts per invocation
    uint pad0;
    uint pad1;
} pc;

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint first = i * pc.per_sum;
    if (first >= pc.n) {
        return;
    }
    uint last = min(first + pc.per_sum, pc.n);
    uvec2 sum = uvec2(0u);
    for (uint k = first; k < last; ++k) {
        uint carry;
        sum.x = uaddCarry(sum.x, counts[k], carry);
        sum.y += carry;
    }
    sums[i] = sum;
}
