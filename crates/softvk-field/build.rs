//! Compiles this crate's kernels (`kernels/`, the repository's `kernels/field/`), with
//! softvk-gpu's headers on the include path.

fn main() {
    softvk_build::compile_kernels("kernels", &[softvk_build::dependency_include("softvk_gpu")]);
}
