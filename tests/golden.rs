//! Golden hashes: the SHA-256 of every file that every `softvk` command writes on small inputs
//! (renders, a gradient, mesh, pose, articulated and sphere-probing fits, a dataset, a few
//! iterations of both reconstruction trainers, reconstruction and its evaluation), as
//! `tools/output-hashes` lists them, against the list committed in `tests/data/golden-hashes.txt`.
//!
//! CI runs this under llvmpipe with 4-, 8- and 16-lane subgroups and with GPU workgroup shapes:
//! the same bytes in all four, since no sum's order depends on the lanes or the workgroups. It
//! checks every other driver too: no kernel leaves a float result to the driver (softvk's own
//! `exp`, `log`, division, square root, `sin` and `cos`, `kernels/gpu/include/fmath.glsl`; no fused
//! operations; fixed-order dot and matrix products), so any conformant device must write these
//! bytes. A device that differs has found a case this reasoning missed (`.ci/gpu-check` lists
//! the files and measures each one's difference from llvmpipe's output, OUT/golden-diff.txt).
//!
//! A change that alters an output on purpose (new arithmetic, a new summation order, a new
//! default) regenerates the list with the binary of that change,
//! `tools/output-hashes target/release/softvk > tests/data/golden-hashes.txt`, and its commit
//! says why and carries the table of `tools/output-hashes --compare OLD_BINARY NEW_BINARY` (the
//! binaries before and after the change): which files changed and by how much, images in 1/255
//! or units in the last place, gradients, losses and weights relative to each number. A list is
//! not re-blessed without it.

mod common;

use std::path::Path;
use std::process::Command;

const GOLDEN: &str = include_str!("data/golden-hashes.txt");

#[test]
fn every_command_writes_the_golden_bytes() {
    let Some(gpu) = common::gpu() else { return };
    let device = gpu.info().name.clone();
    drop(gpu);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new(root.join("tools/output-hashes"))
        .arg(env!("CARGO_BIN_EXE_softvk"))
        .env("SOFTVK_VALIDATION", common::validation_env())
        .output()
        .expect("run tools/output-hashes");
    assert!(
        out.status.success(),
        "tools/output-hashes failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got = String::from_utf8(out.stdout).expect("hash listing is text");
    let lines = |text: &str| -> Vec<(String, String)> {
        text.lines()
            .filter_map(|l| l.split_once("  "))
            .map(|(h, p)| (p.to_string(), h.to_string()))
            .collect()
    };
    let (want, got) = (lines(GOLDEN), lines(&got));
    assert!(
        want.len() > 80,
        "the golden list holds {} files",
        want.len()
    );
    let wrong: Vec<String> = want
        .iter()
        .filter(|w| !got.contains(w))
        .map(|(p, _)| p.clone())
        .chain(
            got.iter()
                .filter(|g| !want.iter().any(|w| w.0 == g.0))
                .map(|(p, _)| format!("{p} (not in the golden list)")),
        )
        .collect();
    assert!(
        wrong.is_empty(),
        "{} of {} files differ from the golden hashes on {device}:\n{}",
        wrong.len(),
        want.len(),
        wrong.join("\n")
    );
}
