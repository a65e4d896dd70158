//! `formation host` (the daemon that lends a machine's CPUs to runs), `formation hosts` (the
//! daemons an orchestrator can reach) and `formation certs` (a CA and per-host certificates for
//! `tls/` endpoints). The daemon itself is [`crate::daemon`]; this module is its command
//! line. See docs/multi-host.md.

use crate::error::HostError;
use formation_net::session::{self, Mode};
use formation_net::tls;
use formation_runtime::link::{ignore_sigpipe, LinkArgs};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Arguments of `formation host`.
#[derive(clap::Args, Debug)]
pub struct HostArgs {
    /// Endpoint to listen on (repeatable): quic/ADDR:PORT (UDP) or tls/ADDR:PORT (TCP; Zenoh
    /// 1.10's TLS link is unsound under traffic, warned) with --tls, tcp/ADDR:PORT (with --auth)
    /// or unixsock-stream/PATH. Default: a Unix socket named after the host in your
    /// private runtime folder, which only your user can connect to.
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
    /// The highest SCHED_FIFO priority this daemon grants a realtime run's agents and its
    /// message path (bridge and Zenoh link threads): `auto` (the default) is 10 when this daemon
    /// may use it (CAP_SYS_NICE or RLIMIT_RTPRIO), else the normal policy; 0: the normal policy
    /// whatever a run asks; 1..=99: at most that. A run asking for more gets this, never more
    /// than this daemon may use itself (a request never raises privileges).
    #[arg(long, default_value = "auto", value_name = "auto|P", value_parser = formation_runtime::run::rt::parse)]
    pub max_rt_priority: formation_runtime::run::rt::Requested,
    /// Link options.
    #[command(flatten)]
    pub link: LinkArgs,
}

/// Arguments of `formation hosts`.
#[derive(clap::Args, Debug)]
pub struct HostsArgs {
    /// Daemon endpoint(s) to ask (repeatable; one client session each): every daemon reachable
    /// through any of them is listed once. Default: every daemon of yours on this machine (its
    /// socket in your private runtime folder).
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
pub fn host_main(a: HostArgs) -> Result<(), HostError> {
    ignore_sigpipe();
    let name = a.name.clone().unwrap_or_else(machine_name);
    if !formation_net::proto::valid_name(&name) {
        return Err(HostError::Name(name));
    }
    // The launcher's own name is refused before anything is printed or opened.
    crate::daemon::check_name(&name)?;
    let listen = if a.listen.is_empty() {
        vec![session::local_endpoint(&name)?]
    } else {
        a.listen.clone()
    };
    let opts = a.link.options(Mode::Daemon, listen, a.connect.clone());
    opts.check()?;
    let exe = formation_runtime::run::self_exe()?;
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
        .unwrap_or_else(|| crate::daemon::default_root(&name));
    // A daemon's agents block on events like the run's plant: no busy loop under SCHED_FIFO.
    let granted = formation_runtime::run::rt::decide(
        a.max_rt_priority,
        false,
        formation_runtime::run::rt::Privilege::of_this_process(),
    )
    .map_err(HostError::MaxRtPriority)?;
    eprintln!(
        "formation host: {name}: a realtime run's agents and message path get at most {granted}"
    );
    let o = crate::daemon::DaemonOptions {
        name,
        session: opts,
        exe,
        root,
        max_rt_priority: granted.priority,
    };
    Ok(crate::daemon::serve(o, &stop)?)
}

/// `formation hosts`: one client session per `--connect` endpoint, all at once, merged by daemon
/// identity (`formation_net::survey`). Exit 2 when no endpoint could be reached at all; an
/// endpoint that cannot be reached while others can is named in a warning.
pub fn hosts_main(a: HostsArgs) -> Result<(), HostError> {
    let mut connect = if a.connect.is_empty() {
        session::local_endpoints()?
    } else {
        a.connect.clone()
    };
    // An endpoint given twice is asked once (one session each).
    let mut seen = std::collections::HashSet::new();
    connect.retain(|ep| seen.insert(ep.clone()));
    // Malformed endpoints or credentials: exit 2 before anything is opened.
    let opts = a.link.options(Mode::Client, vec![], connect.clone());
    opts.check()?;
    let t = Duration::from_millis(a.timeout_ms);
    let survey = formation_net::survey::survey(&opts, t);
    if survey.failed.len() == connect.len() {
        return Err(HostError::Unreachable(survey.failed));
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
    Ok(())
}

/// Arguments of `formation certs`.
#[derive(clap::Args, Debug)]
pub struct CertsArgs {
    /// What to make.
    #[command(subcommand)]
    pub what: CertsCommand,
}

/// `formation certs init` / `issue`.
#[derive(clap::Subcommand, Debug)]
pub enum CertsCommand {
    /// A new certificate authority: DIR/ca.pem and DIR/ca.key (mode 0600; DIR owner-only).
    Init {
        /// The CA's folder (created with mode 0700; keep it on one trusted machine).
        #[arg(long, value_name = "DIR")]
        dir: PathBuf,
    },
    /// A host's key and certificate signed by the CA of --dir, with a copy of the CA certificate:
    /// OUT/ca.pem, OUT/cert.pem, OUT/key.pem (0600; OUT owner-only), the folder to copy to that
    /// host and pass to --tls.
    Issue {
        /// The CA's folder (`formation certs init --dir`).
        #[arg(long, value_name = "DIR")]
        dir: PathBuf,
        /// The host's name (`formation host --name`; the orchestrator's machine needs one too).
        #[arg(long)]
        name: String,
        /// An IP address the host is reached at (`quic/ADDR:PORT` or `tls/ADDR:PORT`; repeatable).
        #[arg(long, value_name = "IP")]
        addr: Vec<std::net::IpAddr>,
        /// A DNS name the host is reached by (repeatable; the --name is one already).
        #[arg(long, value_name = "NAME")]
        dns: Vec<String>,
        /// Where to write the host's folder; default DIR/NAME.
        #[arg(long, value_name = "OUT")]
        out: Option<PathBuf>,
    },
}

/// `formation certs`.
pub fn certs_main(a: CertsArgs) -> Result<(), HostError> {
    let r = match a.what {
        CertsCommand::Init { dir } => tls::init(&dir),
        CertsCommand::Issue {
            dir,
            name,
            addr,
            dns,
            out,
        } => {
            let out = out.unwrap_or_else(|| dir.join(&name));
            tls::issue(
                &dir,
                &tls::Issue {
                    name,
                    addrs: addr,
                    dns,
                },
                &out,
            )
        }
    };
    for f in r? {
        println!("{}", f.display());
    }
    Ok(())
}
