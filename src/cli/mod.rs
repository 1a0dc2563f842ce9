//! The `softvk` binary's side of the command line (SPEC §6): flag groups, image output, and one
//! module per subcommand.
//!
//! This lives in the binary crate (`mod cli;` in `main.rs`), not in the library, on purpose:
//! - every subcommand (`render`, `grad`, `fit-mesh`, `demo`, `fit-pose`, `fit-articulated`,
//!   `fit-field`, `bench`, `dataset`, `train-recon`, `recon`, `eval-recon`; `info` is in
//!   `main.rs`) is a subcommand of this one binary, so the binary crate is the only consumer of
//!   [`args`];
//! - the library is embedded in host engines (`Context::from_raw`); its public API stays free of
//!   clap types, flag spellings and exit-status policy, which are the binary's contract, not the
//!   library's;
//! - tests of the contract run the built binary (`tests/cli.rs`) and compare with library types
//!   built by hand, so the flag → settings mapping is checked independently of this code.
//!
//! What a subcommand needs from here: [`args::ViewArgs`] and [`args::RasterArgs`] (flatten them
//! into its own `clap::Args`), [`output`] to write images atomically,
//! [`render::render_frames`], the one call that renders, and [`interrupt`] (Ctrl-C and SIGTERM
//! end a fit at an iteration boundary, with its checkpoint written).
//!
//! The modules: one per subcommand ([`render`], [`grad`], [`fit_mesh`] with `demo`,
//! [`fit_pose`], [`fit_articulated`], [`fit_field`], [`bench`], [`dataset`], [`train_recon`],
//! [`recon`], [`eval_recon`]) and the shared [`args`], [`output`], [`interrupt`] and
//! [`session`] (the checkpoint flags, progress bar and interrupt check of every fit).

pub mod args;
pub mod bench;
pub mod dataset;
pub mod eval_recon;
pub mod fit_articulated;
pub mod fit_field;
pub mod fit_mesh;
pub mod fit_pose;
pub mod grad;
pub mod interrupt;
pub mod output;
pub mod recon;
pub mod render;
pub mod session;
pub mod train_recon;

/// Turns a clap error into the single line `main` prints after `softvk: error: `.
///
/// clap renders usage errors over several lines (the message, indented continuations such as
/// `[possible values: ...]` or a `tip:`, then `Usage:` and `For more information`); SPEC §6 wants
/// one clear line, so the message and its continuations are kept and joined, and the usage
/// boilerplate is dropped.
pub fn clap_error_line(err: &clap::Error) -> String {
    // `Display` of the rendered error is plain text (styles are stripped).
    let text = err.render().to_string();
    let mut parts: Vec<String> = Vec::new();
    for line in text.lines() {
        let trimmed = line.trim();
        if trimmed.is_empty() {
            continue;
        }
        if trimmed.starts_with("Usage:") || trimmed.starts_with("For more information") {
            break;
        }
        parts.push(
            trimmed
                .strip_prefix("error: ")
                .unwrap_or(trimmed)
                .to_owned(),
        );
    }
    let Some((head, rest)) = parts.split_first() else {
        return format!("{:?}", err.kind());
    };
    if let Some(head) = head.strip_suffix(':') {
        // "the following required arguments were not provided:" and its indented list.
        return format!("{head}: {}", rest.join(", "));
    }
    let mut line = head.clone();
    for p in rest {
        // "[possible values: ...]" completes the sentence; a "tip:" is a second one.
        line.push_str(if p.starts_with('[') { " " } else { "; " });
        line.push_str(p);
    }
    line
}

/// Collapses a multi-line message (a validation layer message, a parser's report) into one line.
pub fn one_line(message: &str) -> String {
    message
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" | ")
}
