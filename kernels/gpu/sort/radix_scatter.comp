#version 460
#extension GL_GOOGLE_include_directive : require
// Radix sort pass, step 2: move every (key, value) to its sorted place for this digit.
// Stability: invocation t owns the ITEMS consecutive elements [t*ITEMS, t*ITEMS + ITEMS) of its
// block, so an element's rank among equal digits is (equal digits in earlier invocations, from a
// workgroup scan) + (equal digits earlier in its own chunk). The 16 per-digit counters of an
// invocation are packed two per uint (16 bits each; a block holds BLOCK = 4096 < 65536 elements), so the
// scan moves 8 words per invocation instead of 16.
#include "radix_config.glsl"
#include "common.glsl"

layout(local_size_x = WG_SIZE) in;

layout(std430, set = 0, binding = 0) readonly buffer KeysIn { uvec2 keys_in[]; };
layout(std430, set = 0, binding = 1) readonly buffer ValsIn { uint vals_in[]; };
layout(std430, set = 0, binding = 2) writeonly buffer KeysOut { uvec2 keys_out[]; };
layout(std430, set = 0, binding = 3) writeonly buffer ValsOut { uint vals_out[]; };
// Exclusive scan of radix_count's histogram (digit-major); with `scan_counts`, the histogram
// itself.
layout(std430, set = 0, binding = 4) readonly buffer Offsets { uint offsets[]; };
// Counted sorts: the number of pairs to sort, at most `n` (read only when `counted` is set).
layout(std430, set = 0, binding = 5) readonly buffer Count { uint count[]; };

layout(push_constant) uniform Push {
    uint n;          // pairs (counted: the capacity)
    uint shift;
    uint n_blocks;
    uint digit_mask;
    uint counted;    // 1: sort only the first min(n, count[0]) pairs; the rest stay in place
    uint copy_tail;  // counted: copy the pairs past the count through to the output
    uint scan_counts; // `offsets` holds the counts: scan them here (few blocks; no scan dispatch)
} pc;

shared uvec4 scan_lo[WG_SIZE]; // packed counters of digits 0..7
shared uvec4 scan_hi[WG_SIZE]; // packed counters of digits 8..15
shared uint digit_offset[RADIX]; // this block's first output position per digit

uint packed_get(uvec4 lo, uvec4 hi, uint digit) {
    uint word = digit < 8u ? lo[(digit >> 1) & 3u] : hi[(digit >> 1) & 3u];
    return (digit & 1u) != 0u ? word >> 16 : word & 0xffffu;
}

void main() {
    uint block = linear_group_id();
    if (block >= pc.n_blocks) {
        return; // surplus group of a folded 2D grid (uniform: the whole workgroup leaves)
    }
    uint n = pc.counted != 0u ? min(pc.n, count[0]) : pc.n;
    uint lid = gl_LocalInvocationIndex;
    uint base = block * BLOCK + lid * ITEMS;
    if (pc.copy_tail != 0u) {
        // Pairs past the count keep their places (in the output too).
        for (uint k = 0; k < ITEMS; ++k) {
            uint i = base + k;
            if (i >= n && i < pc.n) {
                keys_out[i] = keys_in[i];
                vals_out[i] = vals_in[i];
            }
        }
    }
    if (block * BLOCK >= n) {
        return; // uniform: the whole block is past the count
    }

    if (lid < RADIX) {
        // Digit-major: the (digit, block) entry's exclusive prefix sums every entry before it
        // (at most RADIX * n_blocks of them; the host scans here only for a few blocks).
        uint at = lid * pc.n_blocks + block;
        uint before = 0u;
        for (uint j = 0u; j < at * pc.scan_counts; ++j) {
            before += offsets[j];
        }
        digit_offset[lid] = pc.scan_counts != 0u ? before : offsets[at];
    }

    uvec2 key[ITEMS];
    uint val[ITEMS];
    uint digit[ITEMS];
    uint rank_in_chunk[ITEMS];
    uvec4 lo = uvec4(0), hi = uvec4(0);
    for (uint k = 0; k < ITEMS; ++k) {
        uint i = base + k;
        if (i < n) {
            key[k] = keys_in[i];
            val[k] = vals_in[i];
            uint d = key_digit(key[k], pc.shift, pc.digit_mask);
            digit[k] = d;
            rank_in_chunk[k] = packed_get(lo, hi, d);
            uint inc = (d & 1u) != 0u ? 0x10000u : 1u;
            if (d < 8u) {
                lo[(d >> 1) & 3u] += inc;
            } else {
                hi[(d >> 1) & 3u] += inc;
            }
        }
    }

    // Inclusive Hillis-Steele scan of the packed counter vectors, then subtract our own.
    scan_lo[lid] = lo;
    scan_hi[lid] = hi;
    barrier();
    for (uint offset = 1; offset < WG_SIZE; offset <<= 1) {
        uvec4 add_lo = uvec4(0), add_hi = uvec4(0);
        if (lid >= offset) {
            add_lo = scan_lo[lid - offset];
            add_hi = scan_hi[lid - offset];
        }
        barrier();
        scan_lo[lid] += add_lo;
        scan_hi[lid] += add_hi;
        barrier();
    }
    uvec4 before_lo = scan_lo[lid] - lo;
    uvec4 before_hi = scan_hi[lid] - hi;

    for (uint k = 0; k < ITEMS; ++k) {
        uint i = base + k;
        if (i < n) {
            uint d = digit[k];
            uint dst = digit_offset[d] + packed_get(before_lo, before_hi, d) + rank_in_chunk[k];
            keys_out[dst] = key[k];
            vals_out[dst] = val[k];
        }
    }
}
