// Workgroup-wide exclusive prefix sum of one uint per invocation (Hillis-Steele in shared memory).
// Integer adds are exact, so the result does not depend on the order the hardware runs threads in.
// The includer defines WG_SIZE (a power of two) before including this file, and must call it from
// uniform control flow (it contains barriers).
#ifndef SOFTVK_WORKGROUP_SCAN_GLSL
#define SOFTVK_WORKGROUP_SCAN_GLSL

shared uint wgs_buf[2][WG_SIZE];

// Returns the sum of `value` over invocations with a smaller local index; `total` gets the sum over
// the whole workgroup.
uint workgroup_exclusive_scan(uint value, out uint total) {
    uint lid = gl_LocalInvocationIndex;
    uint src = 0;
    wgs_buf[src][lid] = value;
    barrier();
    for (uint offset = 1; offset < WG_SIZE; offset <<= 1) {
        uint acc = wgs_buf[src][lid];
        if (lid >= offset) {
            acc += wgs_buf[src][lid - offset];
        }
        wgs_buf[1 - src][lid] = acc;
        src = 1 - src;
        barrier();
    }
    uint inclusive = wgs_buf[src][lid];
    total = wgs_buf[src][WG_SIZE - 1];
    barrier(); // the buffer may be reused by the next call
    return inclusive - value;
}

#endif
