//! Ctrl-C (SIGINT) and SIGTERM during the long commands (`fit-mesh`, `fit-field`, `fit-pose`,
//! `demo`).
//!
//! The first signal asks the running fit to stop: its progress callback sees [`requested`] and
//! returns `false`, the fit ends after the submission in flight, and the command writes its
//! result and report as a normal end does (every file atomically), marked as interrupted; `main`
//! then says so on stderr and exits with 128 + the signal's number (130 for Ctrl-C, 143 for
//! SIGTERM), as shells report a process killed by it. A second signal stops at once: the
//! temporary files of every write in flight are removed
//! ([`softvk::atomic_file::remove_temporaries_then`]) and the process exits with the same status,
//! leaving no partial or temporary file.
//!
//! The signals are received by a thread of `signal-hook`'s iterator, not in a signal handler, so
//! the second signal's clean-up may take locks and touch files.

use std::sync::atomic::{AtomicI32, Ordering};

use signal_hook::consts::{SIGINT, SIGTERM};
use signal_hook::iterator::Signals;
use softvk::error::{Error, Result};

/// The first signal received (0: none).
static RECEIVED: AtomicI32 = AtomicI32::new(0);

/// Starts receiving SIGINT and SIGTERM (once per process; later calls do nothing).
pub fn install() -> Result<()> {
    static INSTALLED: std::sync::Once = std::sync::Once::new();
    let mut result = Ok(());
    INSTALLED.call_once(|| {
        result = Signals::new([SIGINT, SIGTERM])
            .map_err(|e| Error::Input(format!("cannot watch for interrupts: {e}")))
            .map(|mut signals| {
                std::thread::spawn(move || {
                    for signal in signals.forever() {
                        on_signal(signal);
                    }
                });
            });
    });
    result
}

fn on_signal(signal: i32) {
    if RECEIVED
        .compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst)
        .is_ok()
    {
        eprintln!(
            "\nsoftvk: {}: finishing the work in flight and writing the result (again to stop at \
             once)",
            name(signal)
        );
        return;
    }
    softvk::atomic_file::remove_temporaries_then(|| {
        eprintln!(
            "\nsoftvk: {} again: stopped at once, leaving no partial or temporary file",
            name(signal)
        );
        // `_exit`, not `exit`: the main thread may be inside the Vulkan driver (or its layers),
        // whose exit-time destructors would then crash under it; nothing of ours needs them
        // (stderr is unbuffered, every file is either renamed into place or removed).
        // SAFETY: ends the process; no Rust state is observed afterwards.
        unsafe { libc::_exit(status(signal)) }
    })
}

/// The first signal received, if any: the running fit should stop.
pub fn requested() -> Option<i32> {
    match RECEIVED.load(Ordering::SeqCst) {
        0 => None,
        s => Some(s),
    }
}

/// The signal's usual name.
pub fn name(signal: i32) -> &'static str {
    match signal {
        SIGINT => "interrupted (SIGINT)",
        SIGTERM => "terminated (SIGTERM)",
        _ => "signalled",
    }
}

/// The exit status after `signal`: 128 + its number.
pub fn status(signal: i32) -> i32 {
    128 + signal
}

/// What a resumed run says before its summary: `first` is the first iteration it ran (1 when it
/// did not resume, and nothing is said), `done` the last.
pub fn resumed_note(first: u32, done: u32) -> String {
    match first {
        1 => String::new(),
        first if first > done => format!("resumed after iteration {done}: nothing left to run; "),
        first => format!(
            "resumed after iteration {}: ran iterations {first}..{done}; ",
            first - 1
        ),
    }
}
