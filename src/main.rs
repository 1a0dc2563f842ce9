//! The `softvk` command line.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use softvk::gpu::{Context, ContextOptions};

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
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Info => info(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("softvk: error: {e}");
            ExitCode::FAILURE
        }
    }
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
    println!("  VK_KHR_push_descriptor          yes (required)");
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
