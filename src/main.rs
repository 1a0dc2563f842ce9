//! The `softvk` command line (SPEC §6). Subcommands live in [`cli`]; every error, usage errors
//! included, is one line `softvk: error: ...` on stderr and exit status 1 (a bare `softvk`
//! prints the help instead).

mod cli;

use std::process::ExitCode;

use clap::error::ErrorKind;
use clap::{Parser, Subcommand};
use softvk::gpu::{Context, ContextOptions, DescriptorMode};

#[derive(Parser)]
#[command(
    name = "softvk",
    version,
    about = "Differentiable rendering as Vulkan compute kernels"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print the Vulkan device softvk would use, its driver, limits and features.
    Info,
    /// Render one view of a mesh to an RGBA image (.png 8-bit, or .exr float32).
    Render(Box<cli::render::RenderArgs>),
    /// dL/d(vertex positions) of L = Σ W ⊙ image, as CSV (W an RGBA EXR of the image's size).
    Grad(Box<cli::grad::GradArgs>),
    /// Deform a template mesh to match silhouettes from known cameras (SoftRas's demo).
    FitMesh(Box<cli::fit_mesh::FitMeshArgs>),
    /// Fit the rigid pose (rotation + translation) of a textured mesh to a target RGBA image,
    /// with a σ/γ schedule from blurry to sharp.
    FitPose(Box<cli::fit_pose::FitPoseArgs>),
    /// Fit the joint angles of the built-in skinned figure to a target RGBA image (non-rigid
    /// pose), with σ/γ and blur schedules from soft to sharp.
    FitArticulated(Box<cli::fit_articulated::FitArticulatedArgs>),
    /// Fit an implicit field to silhouettes from known cameras by sphere probing, and write its
    /// surface by marching cubes.
    FitField(Box<cli::fit_field::FitFieldArgs>),
    /// The built-in demo: generate a shape, render its silhouettes, fit a sphere to them, and
    /// write everything to ./softvk-demo/.
    Demo(Box<cli::fit_mesh::DemoArgs>),
    /// Benchmark the forward and backward passes: tiled (per tile size) vs brute force, GPU
    /// timestamps and wall time, as JSON records.
    Bench(Box<cli::bench::BenchArgs>),
    /// Write a procedural single-view reconstruction dataset in the NMR/SoftRas layout
    /// (`<class>_<split>_images.npz`, `<class>_<split>_voxels.npz`) and a contact sheet.
    Dataset(Box<cli::dataset::DatasetArgs>),
    /// Train the single-view reconstruction network on a dataset's silhouettes (SoftRas's
    /// unsupervised 3D learning).
    TrainRecon(Box<cli::train_recon::TrainReconArgs>),
    /// Reconstruct a mesh from one image with a trained model.
    Recon(Box<cli::recon::ReconArgs>),
    /// Score a trained model on the test split (3D IoU per class) beside the retrieval and
    /// mean-shape baselines.
    EvalRecon(Box<cli::eval_recon::EvalReconArgs>),
}

fn main() -> ExitCode {
    // A closed stdout (`softvk info | head -1`) ends the process quietly, as for any Unix tool,
    // instead of a panic with a backtrace from `println!`. Rust sets SIGPIPE to ignored before
    // main; this puts the default back. No other thread exists yet.
    // SAFETY: `signal` with SIG_DFL installs no handler and touches no Rust state.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if !e.use_stderr() => {
            // --help, --version: clap prints them to stdout and they are not errors.
            let _ = e.print();
            return ExitCode::SUCCESS;
        }
        Err(e) if e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            // Bare `softvk`: the help is the answer, on stderr, and the status says "usage".
            let _ = e.print();
            return ExitCode::FAILURE;
        }
        Err(e) => return fail(&cli::clap_error_line(&e)),
    };
    // The fits stop cleanly on a first Ctrl-C / SIGTERM (see `cli::interrupt`).
    if matches!(
        cli.command,
        Command::FitMesh(_)
            | Command::FitPose(_)
            | Command::FitArticulated(_)
            | Command::FitField(_)
            | Command::Demo(_)
            | Command::Dataset(_)
            | Command::TrainRecon(_)
    ) {
        if let Err(e) = cli::interrupt::install() {
            return fail(&e.to_string());
        }
    }
    let result = match &cli.command {
        Command::Info => info(),
        Command::Render(args) => cli::render::run(args),
        Command::Grad(args) => cli::grad::run(args),
        Command::FitMesh(args) => cli::fit_mesh::run(args),
        Command::FitPose(args) => cli::fit_pose::run(args),
        Command::FitArticulated(args) => cli::fit_articulated::run(args),
        Command::FitField(args) => cli::fit_field::run(args),
        Command::Demo(args) => cli::fit_mesh::demo(args),
        Command::Bench(args) => cli::bench::run(args),
        Command::Dataset(args) => cli::dataset::run(args),
        Command::TrainRecon(args) => cli::train_recon::train(args),
        Command::Recon(args) => cli::recon::recon(args),
        Command::EvalRecon(args) => cli::eval_recon::evaluate(args),
    };
    match (result, cli::interrupt::requested()) {
        (Ok(()), None) => ExitCode::SUCCESS,
        (Ok(()), Some(signal)) => {
            let what = if matches!(cli.command, Command::Dataset(_)) {
                "the files written are whole, the rest were not written"
            } else if matches!(cli.command, Command::TrainRecon(_)) {
                "the checkpoint holds the training as it was then (--resume goes on from it)"
            } else {
                "what was written holds the fit as it was then"
            };
            eprintln!(
                "softvk: {}: stopped early; {what}",
                cli::interrupt::name(signal)
            );
            ExitCode::from(cli::interrupt::status(signal) as u8)
        }
        (Err(e), _) => fail(&e.to_string()),
    }
}

/// Prints the one error line and returns the failure status.
fn fail(message: &str) -> ExitCode {
    eprintln!("softvk: error: {}", cli::one_line(message));
    ExitCode::FAILURE
}

fn info() -> softvk::Result<()> {
    let options = ContextOptions::from_env();
    let ctx = Context::new(&options)?;
    let info = ctx.info();
    let l = &info.limits;
    println!("device             {} ({:?})", info.name, info.device_type);
    println!("driver             {}", info.driver);
    println!("vulkan             {}", info.api_version_string());
    println!("subgroup size      {}", info.subgroup_size);
    println!(
        "validation         {}",
        if ctx.validation_enabled() {
            "on (VK_LAYER_KHRONOS_validation)"
        } else {
            "off (SOFTVK_VALIDATION=1 turns it on)"
        }
    );
    let mode = ctx.descriptor_mode();
    println!(
        "descriptors        {} ({})",
        mode.as_str(),
        match mode {
            DescriptorMode::Push => "VK_KHR_push_descriptor; SOFTVK_DESCRIPTORS=sets for sets",
            DescriptorMode::Sets if info.push_descriptor =>
                "cached sets, as SOFTVK_DESCRIPTORS says",
            DescriptorMode::Sets => "cached sets: the device lacks VK_KHR_push_descriptor",
        }
    );
    println!(
        "workgroups         {}",
        if ctx.cpu_workgroups() {
            "shaped for a CPU driver (SOFTVK_WORKGROUPS=gpu for a GPU's)"
        } else if info.device_type == ash::vk::PhysicalDeviceType::CPU {
            "shaped for a GPU, as SOFTVK_WORKGROUPS says"
        } else {
            "shaped for a GPU"
        }
    );
    println!("devices (SOFTVK_DEVICE takes an index or a name substring):");
    for (i, d) in softvk::gpu::list_devices(ctx.instance())?
        .iter()
        .enumerate()
    {
        let mark = if d.handle == ctx.physical_device() {
            "*"
        } else {
            " "
        };
        let status = match &d.usable {
            Ok(_) => "usable".to_string(),
            Err(why) => format!("unusable: {why}"),
        };
        println!("  {mark} {i}: {} ({status})", d.name);
    }
    println!("limits used by softvk:");
    println!(
        "  maxComputeWorkGroupCount        {:?}",
        l.max_compute_work_group_count
    );
    println!(
        "  maxComputeWorkGroupInvocations  {}",
        l.max_compute_work_group_invocations
    );
    println!(
        "  maxComputeSharedMemorySize      {}",
        l.max_compute_shared_memory_size
    );
    println!(
        "  maxStorageBufferRange           {}",
        l.max_storage_buffer_range
    );
    println!(
        "  minStorageBufferOffsetAlignment {}",
        l.min_storage_buffer_offset_alignment
    );
    println!(
        "  nonCoherentAtomSize             {}",
        l.non_coherent_atom_size
    );
    println!(
        "  maxPushConstantsSize            {}",
        l.max_push_constants_size
    );
    println!(
        "  timestampPeriod (ns)            {}",
        info.timestamp_period_ns
    );
    println!(
        "  timestamp valid bits            {}",
        info.timestamp_valid_bits
    );
    println!("features:");
    println!(
        "  VK_KHR_push_descriptor          {} (not required: descriptor sets otherwise)",
        yes(info.push_descriptor)
    );
    println!(
        "  shaderInt64                     {} (not required)",
        yes(info.shader_int64)
    );
    println!(
        "  VK_EXT_shader_atomic_float      {} (not required: gradients reduce without float atomics)",
        yes(info.atomic_float)
    );
    ctx.check_validation()
}

fn yes(b: bool) -> &'static str {
    if b { "yes" } else { "no" }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn usage_errors_become_one_line_without_the_usage_boilerplate() {
        for (args, needle) in [
            (&["softvk", "render"][..], "--mesh"),
            (
                &[
                    "softvk", "render", "--mesh", "m.obj", "--out", "o.png", "--dist", "x",
                ],
                "euclidean",
            ),
            (
                &[
                    "softvk", "render", "--mesh", "m.obj", "--out", "o.png", "--sigmaa", "1",
                ],
                "--sigma",
            ),
            (
                &[
                    "softvk", "render", "--mesh", "m.obj", "--out", "o.png", "--size", "0",
                ],
                "--size",
            ),
            (
                &[
                    "softvk", "render", "--mesh", "m.obj", "--out", "o.png", "--eye", "1",
                ],
                "three",
            ),
            (&["softvk", "frobnicate"], "frobnicate"),
        ] {
            let err = Cli::try_parse_from(args).err().expect("a usage error");
            let line = cli::clap_error_line(&err);
            assert!(
                !line.contains('\n') && !line.contains("Usage"),
                "{args:?}: {line}"
            );
            assert!(!line.starts_with("error"), "{args:?}: {line}");
            assert!(
                line.contains(needle),
                "{args:?}: `{needle}` missing from {line}"
            );
        }
    }
}
