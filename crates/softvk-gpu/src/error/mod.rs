//! The one error type of softvk. Every variant carries enough context (which call, buffer, kernel
//! or input) for its `Display` to be the single line a user sees.
//!
//! It sits at the bottom of softvk's crates, so every crate above fails with it: the errors of
//! the layers above are defined here too — [`MeshError`] (in [`mesh`], re-exported by
//! softvk-raster's `mesh`) and [`RenderError`] (re-exported by `raster::settings`) — since a
//! crate below cannot wrap a type of a crate above.

use ash::vk;

pub mod mesh;

/// How user text appears inside softvk's one-line messages (every crate's errors use it).
pub use crate::text::one_line;
pub use mesh::{Location, MeshError};

/// Why a render could not run.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The mesh breaks an invariant.
    #[error("invalid mesh: {0}")]
    Mesh(#[from] MeshError),
    /// A setting is out of its domain.
    #[error("invalid raster settings: {0}")]
    Settings(String),
    /// Other inputs do not fit together (e.g. a gradient image of the wrong size).
    #[error("invalid input: {0}")]
    Input(String),
}

/// Everything that can go wrong in softvk.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The Vulkan loader (libvulkan) could not be opened.
    #[error(
        "cannot load the Vulkan loader ({0}); install one, e.g. `apt-get install mesa-vulkan-drivers` for the CPU driver lavapipe"
    )]
    Loader(String),

    /// No physical device satisfies softvk's needs (or none matches `SOFTVK_DEVICE`).
    #[error("no usable Vulkan device: {0}")]
    NoDevice(String),

    /// `SOFTVK_VALIDATION=1` asked for the Khronos validation layer and it is not installed.
    #[error(
        "validation was requested but VK_LAYER_KHRONOS_validation is not installed (apt-get install vulkan-validationlayers)"
    )]
    ValidationLayerMissing,

    /// A Vulkan call returned an error code.
    #[error("Vulkan call {call} failed: {result}")]
    Vulkan {
        /// The entry point, e.g. `vkCreateBuffer`.
        call: &'static str,
        /// The error code it returned.
        result: vk::Result,
    },

    /// GPU memory could not be allocated for a named buffer.
    #[error("cannot allocate {size} bytes for buffer `{name}`: {source}")]
    Allocation {
        /// The buffer's debug name.
        name: String,
        /// Requested size in bytes.
        size: u64,
        /// What gpu-allocator said.
        source: gpu_allocator::AllocationError,
    },

    /// A buffer larger than the device can hold was asked for; refused before any Vulkan call.
    #[error(
        "buffer `{name}` needs {size} bytes ({}), more than the device allows: {limit} bytes ({}, {what})",
        human_bytes(*size),
        human_bytes(*limit)
    )]
    BufferTooLarge {
        /// The buffer's debug name.
        name: String,
        /// Requested size in bytes.
        size: u64,
        /// The largest buffer the device allows for this memory kind, in bytes.
        limit: u64,
        /// Which limit that is, e.g. `maxMemoryAllocationSize`.
        what: &'static str,
    },

    /// A kernel was recorded with arguments that do not fit its reflected interface.
    #[error("kernel `{kernel}`: {message}")]
    Kernel {
        /// The kernel's name (its `.comp` file stem).
        kernel: &'static str,
        /// What does not fit.
        message: String,
    },

    /// A request over one of the device's limits, refused before any work was recorded: which
    /// limit, what needed how much of it, the most the device allows, and what to change.
    #[error(
        "{what} needs {need} {}, over the {max} that {device} allows{}",
        kind.unit(),
        if hint.is_empty() { String::new() } else { format!("; {hint}") }
    )]
    DeviceLimit {
        /// Which limit.
        kind: LimitKind,
        /// What asked for it (names the inputs involved).
        what: String,
        /// How much it needed.
        need: u64,
        /// The most the device allows.
        max: u64,
        /// The device's name.
        device: String,
        /// What to change (may be empty).
        hint: &'static str,
    },

    /// A request exceeds what softvk can do otherwise (32-bit indices and counts, a scratch
    /// capacity, a memory kind the device lacks).
    #[error("{0}")]
    Limit(String),

    /// The validation layer reported messages (only when validation is on).
    #[error("the Vulkan validation layer reported {count} message(s); first: {first}")]
    Validation {
        /// How many messages were collected.
        count: usize,
        /// The first one, verbatim.
        first: String,
    },

    /// A call made out of order, or in a state that does not allow it: a bug in the caller,
    /// not bad input (e.g. recording a pass that needs a previous run, or binning into bins
    /// never reserved).
    #[error("{0}")]
    Misuse(String),

    /// A buffer given to a call holds less than the call needs.
    #[error("buffer `{buffer}` holds {have} bytes; {what} needs {need}")]
    BufferTooSmall {
        /// The buffer's debug name.
        buffer: String,
        /// Bytes it holds (of the range given).
        have: u64,
        /// Bytes the call needs there.
        need: u64,
        /// What needs them.
        what: String,
    },

    /// A line of a text input the user gave is malformed (the file and line, and what is wrong).
    #[error("{what} {}:{line}: {message}", path.display())]
    Parse {
        /// What the file is, e.g. `cameras file`.
        what: &'static str,
        /// The file.
        path: std::path::PathBuf,
        /// The line, from 1.
        line: usize,
        /// What is wrong with it.
        message: String,
    },

    /// Bad user input: the message names the input and what is wrong with it.
    #[error("{0}")]
    Input(String),

    /// A mesh could not be loaded, or breaks an invariant (names the file, line or element).
    #[error(transparent)]
    Mesh(#[from] MeshError),

    /// Rendering settings or inputs are out of their domain.
    #[error(transparent)]
    Render(#[from] RenderError),

    /// A self-check failed: two computations that must agree bit for bit did not (the
    /// benchmark checks every tiled render against brute force before timing it).
    #[error("{0}")]
    Check(String),

    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
}

/// Which device limit an [`Error::DeviceLimit`] is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LimitKind {
    /// Loop iterations one shader invocation may run
    /// ([`crate::gpu::DeviceInfo::shader_loop_limit`]: llvmpipe stops a loop after 65 535 and
    /// silently skips the rest, so softvk bounds every loop on the host).
    LoopIterations,
    /// Bytes one storage-buffer binding may span (`maxStorageBufferRange`).
    StorageBinding,
    /// (item, tile) entries one binning may hold (its sort keys and the backward's partials each
    /// in one binding).
    BinEntries,
    /// 16-byte texels one texel-buffer binding may span (`maxTexelBufferElements`): what kernels
    /// read through texel fetches, the gathers llvmpipe vectorizes.
    TexelBinding,
}

impl LimitKind {
    /// What the counts of an [`Error::DeviceLimit`] of this kind count.
    pub fn unit(&self) -> &'static str {
        match self {
            LimitKind::LoopIterations => "loop iterations in one shader invocation",
            LimitKind::StorageBinding => "bytes in one storage-buffer binding",
            LimitKind::BinEntries => "(item, tile) entries in one binning",
            LimitKind::TexelBinding => "texels in one texel-buffer binding",
        }
    }
}

/// softvk's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Attaches the Vulkan entry point's name to an `ash` result.
pub(crate) trait VkContext<T> {
    fn vk(self, call: &'static str) -> Result<T>;
}

impl<T> VkContext<T> for std::result::Result<T, vk::Result> {
    fn vk(self, call: &'static str) -> Result<T> {
        self.map_err(|result| Error::Vulkan { call, result })
    }
}

/// A byte count for people: `512 B`, `1.5 KiB`, `2.00 GiB`, `1024.00 TiB`.
pub(crate) fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["KiB", "MiB", "GiB", "TiB", "PiB"];
    if bytes < 1024 {
        return format!("{bytes} B");
    }
    let mut value = bytes as f64 / 1024.0;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    format!("{value:.2} {}", UNITS[unit])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_device_limit_says_what_how_much_and_what_to_change_on_one_line() {
        let e = Error::DeviceLimit {
            kind: LimitKind::LoopIterations,
            what: "the tiled forward of a tile of 9000 faces".into(),
            need: 70_000,
            max: 65_535,
            device: "llvmpipe".into(),
            hint: "use smaller tiles",
        };
        assert_eq!(
            e.to_string(),
            "the tiled forward of a tile of 9000 faces needs 70000 loop iterations in one shader \
             invocation, over the 65535 that llvmpipe allows; use smaller tiles"
        );
        let e = Error::DeviceLimit {
            kind: LimitKind::StorageBinding,
            what: "points".into(),
            need: 8,
            max: 4,
            device: "d".into(),
            hint: "",
        };
        assert_eq!(
            e.to_string(),
            "points needs 8 bytes in one storage-buffer binding, over the 4 that d allows"
        );
    }

    #[test]
    fn human_bytes_picks_a_unit() {
        assert_eq!(human_bytes(512), "512 B");
        assert_eq!(human_bytes(3 << 29), "1.50 GiB");
        assert_eq!(human_bytes(u64::MAX), "16384.00 PiB");
    }
}
