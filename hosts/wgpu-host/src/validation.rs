//! Our own `VK_EXT_debug_utils` messenger on wgpu's raw instance.
//!
//! wgpu-hal installs a messenger of its own, but it forwards messages to the `log` crate at a
//! severity chosen by `log::max_level()` when the instance is made, and drops a few message ids
//! it considers spurious. A second messenger on the same instance sees every warning and error
//! the layer emits, with its message id name (`SYNC-HAZARD-...`), independent of any logger the
//! application installs.

use std::ffi::{CStr, c_void};
use std::sync::Mutex;

use ash::vk;

/// One message of the validation layer.
#[derive(Clone, Debug)]
pub struct Message {
    /// `WARNING` or `ERROR`.
    pub severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    /// The layer's id name, e.g. `VUID-VkBufferCreateInfo-usage-requiredbitmask` or
    /// `SYNC-HAZARD-READ-AFTER-WRITE` (older layers write `SYNC-HAZARD-READ_AFTER_WRITE`).
    pub id_name: String,
    /// The full text.
    pub text: String,
}

impl Message {
    /// Whether this is a synchronization-validation hazard of `kind` (`READ-AFTER-WRITE`,
    /// `WRITE-AFTER-READ`, ...), however the layer version spells the id.
    pub fn is_hazard(&self, kind: &str) -> bool {
        let id = self.id_name.replace('_', "-");
        id.starts_with("SYNC-HAZARD-") && id.ends_with(&kind.replace('_', "-"))
    }
}

impl std::fmt::Display for Message {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "[{:?}] {}: {}", self.severity, self.id_name, self.text)
    }
}

/// The messages collected so far. Boxed by [`Capture`] so its address, handed to the layer as
/// the callback's user data, never moves.
#[derive(Default)]
struct Log(Mutex<Vec<Message>>);

unsafe extern "system" fn on_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    if data.is_null() || user.is_null() {
        return vk::FALSE;
    }
    // SAFETY: `user` is the boxed `Log` of a live `Capture` (the messenger is destroyed before
    // the box is freed); the layer passes callback data valid for the duration of the call, and
    // its strings, when not null, are NUL-terminated.
    let (log, id_name, text) = unsafe {
        let data = &*data;
        let text = |p: *const std::ffi::c_char| {
            if p.is_null() {
                String::new()
            } else {
                CStr::from_ptr(p).to_string_lossy().into_owned()
            }
        };
        (
            &*(user as *const Log),
            text(data.p_message_id_name),
            text(data.p_message),
        )
    };
    if let Ok(mut messages) = log.0.lock() {
        messages.push(Message {
            severity,
            id_name,
            text,
        });
    }
    vk::FALSE
}

/// A debug-utils messenger that keeps every warning and error of the validation layer.
pub struct Capture {
    loader: ash::ext::debug_utils::Instance,
    messenger: vk::DebugUtilsMessengerEXT,
    log: Box<Log>,
}

impl Capture {
    /// Installs the messenger on `instance`.
    ///
    /// # Safety
    /// `instance` was created from `entry` with `VK_EXT_debug_utils` enabled, and it outlives
    /// the returned capture.
    pub unsafe fn new(entry: &ash::Entry, instance: &ash::Instance) -> Result<Self, vk::Result> {
        let loader = ash::ext::debug_utils::Instance::new(entry, instance);
        let log = Box::<Log>::default();
        let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
            .message_severity(
                vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                    | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
            )
            .message_type(
                vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                    | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                    | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
            )
            .pfn_user_callback(Some(on_message))
            .user_data(&*log as *const Log as *mut c_void);
        // SAFETY: debug_utils is enabled on `instance` (the caller's contract); the user data is
        // the boxed log, which lives until `Drop` has destroyed the messenger.
        let messenger = unsafe { loader.create_debug_utils_messenger(&info, None) }?;
        Ok(Self {
            loader,
            messenger,
            log,
        })
    }

    /// Every message since the last call, oldest first.
    pub fn take(&self) -> Vec<Message> {
        self.log
            .0
            .lock()
            .map(|mut m| std::mem::take(&mut *m))
            .unwrap_or_default()
    }
}

impl Drop for Capture {
    fn drop(&mut self) {
        // SAFETY: the messenger was made by this loader on an instance that is still alive (the
        // caller's contract of `new`); after this no callback can reach `self.log`.
        unsafe {
            self.loader
                .destroy_debug_utils_messenger(self.messenger, None)
        };
    }
}
