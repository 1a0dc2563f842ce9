//! The `softvk` binary as scripts call it.

mod common;

use std::process::Command;

fn softvk() -> Command {
    Command::new(env!("CARGO_BIN_EXE_softvk"))
}

#[test]
fn info_names_the_device_and_the_validation_state() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let out = softvk()
        .arg("info")
        .env("SOFTVK_VALIDATION", "1")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "softvk info failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    for field in [
        "device",
        "driver",
        "vulkan",
        "subgroup size",
        "maxStorageBufferRange",
        "VK_KHR_push_descriptor",
    ] {
        assert!(stdout.contains(field), "`{field}` missing from:\n{stdout}");
    }
    assert!(stdout.contains("validation         on"), "{stdout}");
}

#[test]
fn no_vulkan_driver_gives_one_clear_error_line() {
    // Point the loader at a driver manifest that does not exist: no physical device at all.
    let out = softvk()
        .arg("info")
        .env("VK_ICD_FILENAMES", "/nonexistent/softvk-test-icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/softvk-test-icd.json")
        .env_remove("SOFTVK_VALIDATION")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let ours: Vec<_> = stderr
        .lines()
        .filter(|l| l.starts_with("softvk:"))
        .collect();
    assert_eq!(ours.len(), 1, "expected one error line, got:\n{stderr}");
    assert!(
        ours[0].contains("Vulkan"),
        "the error should say what is missing: {}",
        ours[0]
    );
    assert!(out.stdout.is_empty(), "nothing may be printed on failure");
}

#[test]
fn unknown_device_selection_is_an_error_naming_the_choices() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let out = softvk()
        .arg("info")
        .env("SOFTVK_DEVICE", "no-such-gpu-anywhere")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("SOFTVK_DEVICE=no-such-gpu-anywhere matches none of"),
        "{stderr}"
    );
}
