// Tiling of the LSD radix sort; mirrored by `SORT_BLOCK` and `RADIX_BITS` in src/primitives/sort.rs.
#ifndef SOFTVK_RADIX_CONFIG_GLSL
#define SOFTVK_RADIX_CONFIG_GLSL
#define WG_SIZE 256
#define ITEMS 16
#define BLOCK (WG_SIZE * ITEMS)
#define RADIX_BITS 4
#define RADIX (1 << RADIX_BITS)

// Keys are u64 stored as uvec2 (lo, hi), so no shaderInt64 is needed. `shift` is a multiple of
// RADIX_BITS, so a digit never straddles the two words.
// `digit_mask` is RADIX - 1, or fewer bits on the last pass when the key width is not a multiple
// of RADIX_BITS.
uint key_digit(uvec2 key, uint shift, uint digit_mask) {
    uint word = shift < 32u ? key.x : key.y;
    return (word >> (shift & 31u)) & digit_mask;
}
#endif
