#version 460
#extension GL_GOOGLE_include_directive : require
// Radix sort of one block (n <= BLOCK pairs), every pass in one workgroup and one dispatch. The
// multi-workgroup sort spends three dispatches a pass (count, scan, scatter); on llvmpipe a
// dispatch costs about 0.1 ms whatever its size, which dominates a sort of a few thousand pairs
// such as the grid field's backward runs every iteration (its anchors by cell, 17 bits: five
// passes). One workgroup needs no global barrier between a pass's counts and its scatter.
//
// The same stable LSD passes as radix_count + radix_scatter, RADIX_BITS bits each (a stable
// sort's result is unique): invocation t owns the ITEMS consecutive pairs [t*ITEMS, t*ITEMS +
// ITEMS); a pair goes to (first position of its digit) + (equal digits in earlier invocations,
// from a workgroup scan) + (equal digits earlier in its own chunk); the scan's totals give the
// digits' first positions.
//
// The pairs ping-pong inside `KeysAlt`/`ValsAlt` (two halves of n), so every pass reads and
// writes one binding whatever its parity: the pairs are copied in first and back at the end.
#include "radix_config.glsl"

layout(local_size_x = WG_SIZE) in;

// Each invocation reads and writes the same pairs of these (copied in, then back).
layout(std430, set = 0, binding = 0) buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 1) buffer Vals { uint vals[]; };
// 2n pairs: the ping-pong halves [0, n) and [n, 2n), written and read across invocations.
layout(std430, set = 0, binding = 2) coherent buffer KeysAlt { uvec2 keys_alt[]; };
layout(std430, set = 0, binding = 3) coherent buffer ValsAlt { uint vals_alt[]; };

layout(push_constant) uniform Push {
    uint n;
    uint key_bits;  // the low key_bits bits are sorted, RADIX_BITS a pass
} pc;

// Per-invocation packed digit counters (16 bits each, two per word: a block holds
// BLOCK = 4096 < 65536 pairs), scanned across the workgroup.
shared uvec4 scan_lo[WG_SIZE]; // digits 0..7
shared uvec4 scan_hi[WG_SIZE]; // digits 8..15
// Two-level scan: ROWS rows of ROW invocations.
#define ROW 16u
#define ROWS (WG_SIZE / ROW)
shared uvec4 row_lo[ROWS];
shared uvec4 row_hi[ROWS];
// Each digit's first output position in this pass.
shared uint first_pos[RADIX];

uint packed_get(uvec4 lo, uvec4 hi, uint digit) {
    uint word = digit < 8u ? lo[(digit >> 1) & 3u] : hi[(digit >> 1) & 3u];
    return (digit & 1u) != 0u ? word >> 16 : word & 0xffffu;
}

void packed_add(inout uvec4 lo, inout uvec4 hi, uint digit) {
    uint inc = (digit & 1u) != 0u ? 0x10000u : 1u;
    if (digit < 8u) {
        lo[(digit >> 1) & 3u] += inc;
    } else {
        hi[(digit >> 1) & 3u] += inc;
    }
}

// Exclusive scan of (lo, hi) across the workgroup in invocation order; returns this
// invocation's prefix and leaves the workgroup's totals in row_lo/row_hi[ROWS - 1] (inclusive).
// Rows are scanned serially by one invocation each, then the row totals by every invocation:
// three barriers, where a Hillis-Steele scan takes sixteen (each a coroutine switch per 8-lane
// vector on llvmpipe).
void workgroup_scan(uvec4 lo, uvec4 hi, out uvec4 before_lo, out uvec4 before_hi) {
    uint lid = gl_LocalInvocationIndex;
    barrier(); // the previous scan's readers are done
    scan_lo[lid] = lo;
    scan_hi[lid] = hi;
    barrier();
    if (lid < ROWS) {
        uvec4 acc_lo = uvec4(0), acc_hi = uvec4(0);
        for (uint k = 0u; k < ROW; ++k) {
            uint j = lid * ROW + k;
            uvec4 l = scan_lo[j], h = scan_hi[j];
            scan_lo[j] = acc_lo;
            scan_hi[j] = acc_hi;
            acc_lo += l;
            acc_hi += h;
        }
        row_lo[lid] = acc_lo;
        row_hi[lid] = acc_hi;
    }
    barrier();
    before_lo = scan_lo[lid];
    before_hi = scan_hi[lid];
    uint row = lid / ROW;
    for (uint r = 0u; r < row; ++r) {
        before_lo += row_lo[r];
        before_hi += row_hi[r];
    }
}

void main() {
    uint lid = gl_LocalInvocationIndex;
    uint n = pc.n;
    for (uint i = lid; i < n; i += WG_SIZE) {
        keys_alt[i] = keys[i];
        vals_alt[i] = vals[i];
    }
    memoryBarrierBuffer();
    barrier();

    uint passes = (pc.key_bits + RADIX_BITS - 1u) / RADIX_BITS;
    uint base = lid * ITEMS;
    uint src = 0u;
    uint dst = n;
    for (uint pass = 0u; pass < passes; ++pass) {
        uint shift = pass * RADIX_BITS;
        uint digit_mask = (1u << min(pc.key_bits - shift, RADIX_BITS)) - 1u;
        uvec2 key[ITEMS];
        uint val[ITEMS];
        uint digit[ITEMS];
        uint rank_in_chunk[ITEMS];
        uvec4 lo = uvec4(0), hi = uvec4(0);
        for (uint k = 0u; k < ITEMS; ++k) {
            uint i = base + k;
            if (i < n) {
                key[k] = keys_alt[src + i];
                val[k] = vals_alt[src + i];
                uint d = key_digit(key[k], shift, digit_mask);
                digit[k] = d;
                rank_in_chunk[k] = packed_get(lo, hi, d);
                packed_add(lo, hi, d);
            }
        }
        uvec4 before_lo, before_hi;
        workgroup_scan(lo, hi, before_lo, before_hi);
        // The block is the whole array: its digit totals give each digit's first position.
        if (lid == 0u) {
            uvec4 tot_lo = uvec4(0), tot_hi = uvec4(0);
            for (uint r = 0u; r < ROWS; ++r) {
                tot_lo += row_lo[r];
                tot_hi += row_hi[r];
            }
            uint pos = 0u;
            for (uint d = 0u; d < RADIX; ++d) {
                first_pos[d] = pos;
                pos += packed_get(tot_lo, tot_hi, d);
            }
        }
        barrier();
        for (uint k = 0u; k < ITEMS; ++k) {
            uint i = base + k;
            if (i < n) {
                uint d = digit[k];
                uint to = dst + first_pos[d] + packed_get(before_lo, before_hi, d)
                    + rank_in_chunk[k];
                keys_alt[to] = key[k];
                vals_alt[to] = val[k];
            }
        }
        // This pass's output is the next one's input, written by other invocations.
        memoryBarrierBuffer();
        barrier();
        uint t = src;
        src = dst;
        dst = t;
    }

    for (uint i = lid; i < n; i += WG_SIZE) {
        keys[i] = keys_alt[src + i];
        vals[i] = vals_alt[src + i];
    }
}
