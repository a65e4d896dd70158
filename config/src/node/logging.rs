//! `tracing` set-up of every formation process: `RUST_LOG` (default `info`), one log file per
//! process under `<run dir>/logs/<role>[-<agent>].log`, and optionally a console on stderr.
//!
//! A log file is appended to, never truncated: a restarted agent process continues the file of
//! the one it replaces (whose last lines name why it died) after a separator line naming its pid.
//! It is opened without following a symbolic link at its name (`files::open_append`), in a
//! `logs/` folder created owner-only.

use super::error::NodeError;
use std::io::IsTerminal;
use std::path::Path;
use std::sync::Mutex;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::{fmt, EnvFilter, Layer};

/// Log file name of a process: `plant`, `leader`, `orchestrator`, or `agent-<i>` with i 1-based.
pub fn log_file_name(role: &str, agent: Option<usize>) -> String {
    match agent {
        Some(i) => format!("{role}-{}.log", i + 1),
        None => format!("{role}.log"),
    }
}

/// The line between the log of a process and that of the next one appending to the same file.
pub fn separator(pid: u32) -> String {
    format!("---- new process: pid {pid} (the lines above are an earlier process's) ----\n")
}

/// Whether the console log may use colour: stderr is a terminal and `NO_COLOR` is unset or empty
/// (https://no-color.org).
fn colour_on_stderr() -> bool {
    std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty())
}

/// The log filter without `RUST_LOG`: info, and only errors of RustDDS (`--ros2`, crate
/// formation-ros2), which reports routine discovery events (a peer gone, a locator it does not
/// use) as warnings, hundreds a run.
const DEFAULT_FILTER: &str = "info,rustdds=error";

/// Installs the global subscriber: a file layer writing to `<run_dir>/logs/<name>` (created if
/// needed) and, if `console`, a compact layer on stderr. Returns an error text (logging then stays
/// off or console-only) when the file cannot be created; never panics.
pub fn init(run_dir: &Path, file_name: &str, console: bool) -> Result<(), NodeError> {
    let filter =
        || EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(DEFAULT_FILTER));
    let dir = run_dir.join("logs");
    let file = super::files::ensure_private_dir(&dir)
        .map_err(std::io::Error::from)
        .and_then(|()| super::files::open_append(&dir.join(file_name)))
        .and_then(|mut f| {
            if f.metadata()?.len() > 0 {
                use std::io::Write;
                f.write_all(separator(std::process::id()).as_bytes())?;
            }
            Ok(f)
        })
        .map_err(|e| NodeError::File {
            path: dir.join(file_name),
            detail: format!("cannot create: {e}"),
        });
    let file_layer = file.as_ref().ok().map(|f| {
        let f = f.try_clone().ok().map(Mutex::new);
        f.map(|w| {
            fmt::layer()
                .with_ansi(false)
                .with_writer(w)
                .with_filter(filter())
        })
    });
    let console_layer = console.then(|| {
        fmt::layer()
            .compact()
            .without_time()
            .with_target(false)
            .with_ansi(colour_on_stderr())
            .with_writer(std::io::stderr)
            .with_filter(filter())
    });
    let _ = tracing_subscriber::registry()
        .with(file_layer.flatten())
        .with(console_layer)
        .try_init();
    file.map(|_| ())
}
