//! Compiles this crate's kernels (`kernels/`, the repository's `kernels/gpu/`) and tells the
//! crates above where its GLSL headers are.

fn main() {
    softvk_build::export_include("kernels");
    softvk_build::compile_kernels("kernels", &[]);
}
