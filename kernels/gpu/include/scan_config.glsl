// Tiling of the multi-level scan; mirrored by `SCAN_BLOCK` in src/primitives/scan.rs (which
// says why the block is this large).
#ifndef SOFTVK_SCAN_CONFIG_GLSL
#define SOFTVK_SCAN_CONFIG_GLSL
#define WG_SIZE 256
#define ITEMS 32
#define BLOCK (WG_SIZE * ITEMS)
#endif
