//! Compiles the top crate's kernels (`kernels/softvk/`: fits, fields and probing, networks,
//! reconstruction) with softvk-gpu's headers on the include path.

fn main() {
    softvk_build::compile_kernels(
        "kernels/softvk",
        &[softvk_build::dependency_include("softvk_gpu")],
    );
}
