//! `formation host` (the daemon that lends a machine's CPUs to runs) and `formation hosts` (the
//! daemons an orchestrator can reach). The daemon itself is `formation_net::daemon`; this module
//! is its command line. See docs/multi-host.md.

use crate::cli;
use formation_net::session::{self, Mode, Options};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Zenoh link options shared by `host`, `hosts` and `run --hosts`.
#[derive(clap::Args, Debug, Clone)]
pub struct LinkArgs {
    /// `user:password` file (mode 0600): a daemon accepts only orchestrators that present one of
    /// its lines; an orchestrator presents its first line. Required to listen beyond loopback.
    #[arg(long, value_name = "FILE")]
    pub auth: Option<PathBuf>,
    /// Zenoh link lease, ms: a host whose link stays silent this long is declared lost (a killed
    /// daemon is seen at once, its TCP link closes).
    #[arg(long, default_value_t = session::DEFAULT_LEASE_MS, value_name = "MS")]
    pub lease_ms: u64,
}

/// Arguments of `formation host`.
#[derive(clap::Args, Debug)]
pub struct HostArgs {
    /// Endpoint to listen on (repeatable). Default: loopback only; anything else needs --auth.
    #[arg(long, value_name = "ENDPOINT")]
    pub listen: Vec<String>,
    /// Endpoint of another daemon or router to connect to (repeatable).
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// This host's name in placements (`--place 4,5@NAME`); default: the machine's host name.
    #[arg(long)]
    pub name: Option<String>,
    /// Folder for the run folders (created with mode 0700).
    #[arg(long, value_name = "DIR")]
    pub root: Option<PathBuf>,
    /// The highest SCHED_FIFO priority this daemon grants a run's agents (0..=99). A run asking
    /// for more (`formation run --realtime --rt-priority P`) gets this; 0, the default: the agents
    /// run under the normal policy whatever a run asks (a request never raises privileges).
    #[arg(long, default_value_t = 0, value_name = "P", value_parser = clap::value_parser!(u32).range(0..=99))]
    pub max_rt_priority: u32,
    /// Link options.
    #[command(flatten)]
    pub link: LinkArgs,
}

/// Arguments of `formation hosts`.
#[derive(clap::Args, Debug)]
pub struct HostsArgs {
    /// Daemon endpoint(s) to ask (repeatable; one client session each): every daemon reachable
    /// through any of them is listed once. Default tcp/127.0.0.1:7447.
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// How long to wait for answers, ms.
    #[arg(long, default_value_t = 1500, value_name = "MS")]
    pub timeout_ms: u64,
    /// JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Link options.
    #[command(flatten)]
    pub link: LinkArgs,
}

/// The machine's host name, made key-safe (`[A-Za-z0-9_-]`, at most 32).
pub fn machine_name() -> String {
    let raw = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
    let s: String = raw
        .trim()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '-'
            }
        })
        .take(32)
        .collect();
    if s.is_empty() {
        "host".into()
    } else {
        s
    }
}

/// `formation host`.
pub fn host_main(a: HostArgs) -> ExitCode {
    let name = a.name.clone().unwrap_or_else(machine_name);
    let listen = if a.listen.is_empty() {
        vec![session::default_endpoint()]
    } else {
        a.listen.clone()
    };
    let opts = Options {
        mode: Mode::Daemon,
        listen,
        connect: a.connect.clone(),
        auth: a.link.auth.clone(),
        lease_ms: a.link.lease_ms,
    };
    if let Err(e) = opts.check() {
        eprintln!("error: {e}");
        return ExitCode::from(cli::EXIT_INVALID);
    }
    let exe = match crate::run::self_exe() {
        Ok(e) => e,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(1);
        }
    };
    let stop = Arc::new(AtomicBool::new(false));
    {
        let s = stop.clone();
        if let Err(e) = ctrlc::set_handler(move || s.store(true, Ordering::SeqCst)) {
            eprintln!("warning: cannot install the signal handler: {e}");
        }
    }
    formation_config::node::ipc::quiet_log();
    // The daemon's and its bridges' warnings on stderr (`RUST_LOG`, default warn).
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .try_init();
    let root = a
        .root
        .clone()
        .unwrap_or_else(|| formation_net::daemon::default_root(&name));
    let o = formation_net::daemon::DaemonOptions {
        name,
        session: opts,
        exe,
        root,
        max_rt_priority: a.max_rt_priority,
    };
    match formation_net::daemon::serve(o, &stop) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(cli::EXIT_INVALID)
        }
    }
}

/// `formation hosts`: one client session per `--connect` endpoint, all at once, merged by daemon
/// identity (`formation_net::survey`). Exit 2 when no endpoint could be reached at all; an
/// endpoint that cannot be reached while others can is named in a warning.
pub fn hosts_main(a: HostsArgs) -> ExitCode {
    let mut connect = if a.connect.is_empty() {
        vec![session::default_endpoint()]
    } else {
        a.connect.clone()
    };
    // An endpoint given twice is asked once (one session each).
    let mut seen = std::collections::HashSet::new();
    connect.retain(|ep| seen.insert(ep.clone()));
    // Malformed endpoints or credentials: exit 2 before anything is opened.
    let opts = Options {
        mode: Mode::Client,
        listen: vec![],
        connect: connect.clone(),
        auth: a.link.auth.clone(),
        lease_ms: a.link.lease_ms,
    };
    if let Err(e) = opts.check() {
        eprintln!("error: {e}");
        return ExitCode::from(cli::EXIT_INVALID);
    }
    let t = Duration::from_millis(a.timeout_ms);
    let survey = formation_net::survey::survey(&connect, a.link.auth.clone(), a.link.lease_ms, t);
    if survey.failed.len() == connect.len() {
        for (ep, e) in &survey.failed {
            eprintln!("error: {ep}: {e}");
        }
        return ExitCode::from(cli::EXIT_INVALID);
    }
    for (ep, e) in &survey.failed {
        eprintln!("warning: {ep}: {e}");
    }
    let infos = &survey.hosts;
    if a.json {
        println!("{}", serde_json::to_string_pretty(infos).unwrap());
    } else {
        println!(
            "{:<16} {:<28} {:>4} {:>4}  BUILD",
            "NAME", "ADDRESS", "CPUS", "RUNS"
        );
        for l in infos {
            let i = &l.info;
            println!(
                "{:<16} {:<28} {:>4} {:>4}  {} (protocol {})",
                i.name,
                i.listen.join(","),
                i.cpus,
                i.runs,
                i.identity.build,
                i.identity.protocol
            );
        }
        if infos.is_empty() {
            eprintln!("no host answered within {t:?} (start one with `formation host`)");
        }
    }
    ExitCode::SUCCESS
}
