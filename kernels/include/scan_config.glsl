// Tiling of the multi-level scan; mirrored by `SCAN_BLOCK` in src/gpu/scan.rs.
#ifndef SOFTVK_SCAN_CONFIG_GLSL
#define SOFTVK_SCAN_CONFIG_GLSL
#define WG_SIZE 256
#define ITEMS 16
#define BLOCK (WG_SIZE * ITEMS)
#endif
