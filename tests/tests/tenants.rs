//! Each run is its own security domain (docs/multi-host.md, "Threat model"): a second tenant who
//! holds a daemon's credentials can reach the daemon and every key of the Zenoh network, but can
//! neither drive nor inject into a run that is not its own, and hostile traffic on every key a
//! daemon or bridge listens on leaves the daemon up, the run byte-identical to `formation sim`,
//! and the logs bounded.
//!
//! Setup: a `formation host` daemon in its own mount namespace (its own /dev/shm and /tmp, so no
//! shared memory crosses) on a loopback TCP endpoint with `--auth`; the orchestrator on this
//! machine places agents 4 and 5 on it; the attacker is a plain Zenoh client of this test
//! (`formation_net::probe`) with the same credentials. Needs root (mount namespaces): skipped
//! with a message otherwise, and required (a failure) when `FORMATION_REQUIRE_NETNS=1` (set by
//! `.ci/run`, which runs as root).

use formation_config::protocol::wire::VehicleState;
use formation_net::bridge::{encode_frame, Record};
use formation_net::probe::Probe;
use formation_net::proto::{self, Reply, Request};
use formation_tests::bin;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

static NEXT: AtomicUsize = AtomicUsize::new(0);

/// The two tests run one after the other: each is a whole split run under attack, and two at once
/// on a 2-core machine measure the machine, not the daemon.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// `true`: run the test; `false`: skipped (panics instead when FORMATION_REQUIRE_NETNS=1).
fn available(test: &str) -> bool {
    // SAFETY: geteuid has no preconditions.
    let why = if unsafe { libc::geteuid() } != 0 {
        Some("not root (a daemon with its own /dev/shm needs a mount namespace)")
    } else if !Command::new("unshare")
        .arg("--version")
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
    {
        Some("the `unshare` command (util-linux) is missing")
    } else {
        None
    };
    match why {
        None => true,
        Some(why) if std::env::var("FORMATION_REQUIRE_NETNS").as_deref() == Ok("1") => {
            panic!("{test}: FORMATION_REQUIRE_NETNS=1 but {why}")
        }
        Some(why) => {
            eprintln!("skipping {test}: {why}");
            false
        }
    }
}

/// A folder for the test's files outside /tmp (the daemon has its own /tmp).
fn work_dir(tag: &str) -> PathBuf {
    formation_tests::work_dir_beside_binaries("tenant-tests", tag)
}

/// A daemon `t1` in its own mount namespace on a loopback port, killed on drop.
struct Daemon {
    child: Child,
    port: usize,
    endpoint: String,
    auth: PathBuf,
    log: PathBuf,
}

impl Daemon {
    fn start(dir: &Path) -> Daemon {
        use std::os::unix::fs::PermissionsExt;
        let auth = dir.join("auth");
        std::fs::write(&auth, "formation:tests-only-secret\n").unwrap();
        std::fs::set_permissions(&auth, std::fs::Permissions::from_mode(0o600)).unwrap();
        let port = 17_000
            + (std::process::id() as usize % 1000) * 4
            + NEXT.fetch_add(1, Ordering::SeqCst) % 4;
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let log = dir.join("daemon.log");
        let mut child = Command::new("unshare")
            .args(["--mount", "--propagation", "private", "sh", "-c"])
            .arg("mount -t tmpfs -o mode=1777 tmpfs /dev/shm && mount -t tmpfs -o mode=1777 tmpfs /tmp || exit 97\nexec \"$@\"")
            .arg("sh")
            .arg(bin("formation"))
            .args(["host", "--name", "t1", "--listen", &endpoint, "--auth"])
            .arg(&auth)
            .env_remove("CARGO")
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .expect("formation host starts");
        formation_tests::wait_until_listening(
            &mut child,
            &log,
            "the daemon",
            Duration::from_secs(20),
        );
        Daemon {
            child,
            port,
            endpoint,
            auth,
            log,
        }
    }

    /// The daemon's resident memory now and at its peak (`VmRSS`, `VmHWM` of
    /// /proc/<pid>/status), in bytes. The child is the daemon itself: `unshare` and `sh` exec it.
    fn memory(&self) -> (u64, u64) {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id()))
            .expect("the daemon's status is readable");
        let kib = |key: &str| -> u64 {
            status
                .lines()
                .find_map(|l| l.strip_prefix(key))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
                .unwrap_or_else(|| panic!("{key} in the daemon's status:\n{status}"))
                * 1024
        };
        (kib("VmRSS:"), kib("VmHWM:"))
    }

    fn alive(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        // SAFETY: kill(2) on our own child.
        unsafe { libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM) };
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(10) {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The paper scenario for `duration` s, agents 4 and 5 on the daemon.
fn run_args(duration: &str) -> Vec<String> {
    vec!["--set".into(), format!("simulation.duration_s={duration}")]
}

/// Starts `formation run` with agents 4 and 5 on `d`; its stderr goes to `err`.
fn start_run(d: &Daemon, dir: &Path, args: &[String], extra: &[&str]) -> (Child, PathBuf, PathBuf) {
    let out = dir.join("run");
    let err = dir.join("run.err");
    let child = Command::new(bin("formation"))
        .arg("run")
        .args(args)
        .args([
            "--hosts",
            "t1",
            "--place",
            "4,5@t1",
            "--connect",
            &d.endpoint,
            "--auth",
        ])
        .arg(&d.auth)
        .args(extra)
        .arg("--out")
        .arg(&out)
        .env_remove("CARGO")
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&err).unwrap())
        .spawn()
        .expect("formation run starts");
    (child, out, err)
}

/// The bytes of a `#[repr(C)]` wire value.
fn bytes_of<T: Copy>(v: &T) -> Vec<u8> {
    // SAFETY: a wire type without uninitialised padding (every padding is an explicit field).
    unsafe { std::slice::from_raw_parts(v as *const T as *const u8, std::mem::size_of::<T>()) }
        .to_vec()
}

/// A well-formed frame that moves agent 4 far away, as if sent by `from`.
fn forged_frame(from: &str) -> Vec<u8> {
    let s = VehicleState {
        agent: 3,
        position: [500.0, -500.0, 300.0],
        ..VehicleState::default()
    };
    let state = bytes_of(&s);
    encode_frame(&[
        Record::From(from),
        Record::Sample {
            name: "formation/agent/3/state",
            type_name: "formation.v3.VehicleState",
            bytes: &state,
        },
        Record::Event("formation/wake/agent/3"),
    ])
}

/// Every request a tenant could send about run `id`, without proof of its secret, with a wrong
/// proof, and with a well-formed request for a run that does not exist.
fn foreign_requests(id: &str) -> Vec<Vec<u8>> {
    let reqs = [
        Request::Signal {
            run_id: id.into(),
            agent: 3,
            signal: libc::SIGSTOP,
        },
        Request::Kill {
            run_id: id.into(),
            agent: 3,
        },
        Request::Checkpoint {
            run_id: id.into(),
            agent: 3,
        },
        Request::Spawn {
            run_id: id.into(),
            agent: 3,
            rejoin_at: Some(100),
        },
        Request::Replan {
            run_id: id.into(),
            agent_hosts: vec!["local".into(); 5],
        },
        Request::Report { run_id: id.into() },
        Request::End { run_id: id.into() },
    ];
    let mut v = Vec::new();
    for r in &reqs {
        v.push(proto::frame(r, b""));
        let mut wrong = proto::frame(r, b"rejoin bytes of the attacker's choosing");
        wrong.extend_from_slice(&[7u8; 40]);
        v.push(wrong);
    }
    v
}

/// Sends `payload` to the daemon's request key; every answer must be a refusal.
fn assert_refused(p: &Probe, payload: Vec<u8>) -> String {
    let answers = p
        .query(
            "formation/host/t1/req",
            Some(payload),
            Duration::from_secs(5),
        )
        .expect("the query goes out");
    assert!(!answers.is_empty(), "the daemon answers");
    let mut why = String::new();
    for a in answers {
        let a = a.expect("an answer, not an error reply");
        match serde_json::from_slice::<Reply>(&a) {
            Ok(Reply::Refused(w)) => why = w,
            other => panic!("a foreign request was not refused: {other:?}"),
        }
    }
    why
}

/// Waits for the run to end; its exit code and stderr.
fn finish(mut child: Child, err: &Path) -> (i32, String) {
    let st = child.wait().unwrap();
    let mut text = String::new();
    std::fs::File::open(err)
        .unwrap()
        .read_to_string(&mut text)
        .unwrap();
    (st.code().unwrap_or(-1), text)
}

#[test]
fn a_second_tenant_with_the_daemons_credentials_can_neither_drive_nor_inject_into_anothers_run() {
    let test = "a_second_tenant_with_the_daemons_credentials_can_neither_drive_nor_inject_into_anothers_run";
    if !available(test) {
        return;
    }
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let dir = work_dir("tenant");
    let mut d = Daemon::start(&dir);
    let args = run_args("20");
    let (run, out, err) = start_run(&d, &dir, &args, &[]);
    let p = Probe::open(&d.endpoint, Some(d.auth.clone())).expect("the tenant connects");
    let ids = p.run_ids(Duration::from_secs(30));
    assert_eq!(ids.len(), 1, "the tenant sees the run's token: {ids:?}");
    let id = &ids[0];
    // The tenant records the real frames to the daemon, to replay them.
    let cap = p
        .capture(&format!("formation/run/{id}/to/t1"), 200)
        .unwrap();
    let mut refusals = Vec::new();
    let mut replayed = 0;
    let mut forged = 0;
    let t0 = Instant::now();
    let mut run = Some(run);
    while run
        .as_mut()
        .is_some_and(|r| matches!(r.try_wait(), Ok(None)))
    {
        for req in foreign_requests(id) {
            refusals.push(assert_refused(&p, req));
        }
        for to in ["t1", "local"] {
            for from in ["local", "t1", "x"] {
                let mut f = forged_frame(from);
                p.put(&format!("formation/run/{id}/to/{to}"), f.clone())
                    .unwrap();
                f.extend_from_slice(&[1u8; 40]);
                p.put(&format!("formation/run/{id}/to/{to}"), f).unwrap();
                forged += 2;
            }
        }
        for f in cap.take() {
            p.put(&format!("formation/run/{id}/to/t1"), f).unwrap();
            replayed += 1;
        }
        std::thread::sleep(Duration::from_millis(100));
        assert!(
            t0.elapsed() < Duration::from_secs(180),
            "the run did not end"
        );
    }
    let (code, err_text) = finish(run.take().unwrap(), &err);
    assert_eq!(code, 0, "the attacked run failed:\n{err_text}");
    assert!(
        refusals.len() >= 14,
        "the attack ran: {} requests",
        refusals.len()
    );
    for why in &refusals {
        // Refused for want of proof while the run is held there; once it has ended there, as
        // unknown.
        assert!(
            why.contains("proof of the run's secret") || why.contains("no run"),
            "a refusal names the missing proof: {why}"
        );
        assert!(
            !why.contains("/tmp") && !why.contains("/run/"),
            "a refusal names no path: {why}"
        );
    }
    assert!(
        refusals.iter().filter(|w| w.contains("proof")).count() >= 14,
        "the requests came while the run was held: {refusals:?}"
    );
    assert!(forged >= 12, "forged frames were sent: {forged}");
    assert!(replayed > 0, "real frames were captured and replayed");
    assert!(d.alive(), "the daemon is up: {}", d.log());
    let log = d.log();
    assert!(
        log.contains("refused"),
        "the daemon says what it refused:\n{log}"
    );
    formation_tests::assert_trajectory_is_sims(
        &out,
        &args.iter().map(String::as_str).collect::<Vec<_>>(),
        &dir.join("sim"),
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn every_key_a_daemon_or_bridge_listens_on_takes_fuzz_with_the_daemon_up_the_run_intact_and_logs_bounded(
) {
    let test = "every_key_a_daemon_or_bridge_listens_on_takes_fuzz_with_the_daemon_up_the_run_intact_and_logs_bounded";
    if !available(test) {
        return;
    }
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
    let dir = work_dir("fuzz");
    let mut d = Daemon::start(&dir);
    let args = run_args("20");
    // The run also exports its telemetry (`--zenoh-listen`): its info key is fuzzed too.
    let export = format!("tcp/127.0.0.1:{}", d.port + 10_000);
    let (run, out, err) = start_run(&d, &dir, &args, &["--zenoh-listen", &export]);
    let p = Probe::open(&d.endpoint, Some(d.auth.clone())).expect("the fuzzer connects");
    let ids = p.run_ids(Duration::from_secs(30));
    assert_eq!(ids.len(), 1, "{ids:?}");
    let id = &ids[0];
    let e = Probe::open(&export, Some(d.auth.clone())).expect("the fuzzer reaches the export");
    let (rss_before, _) = d.memory();
    let export_info = formation_net::export::info_key(id);
    // Deterministic noise.
    let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut noise = |n: usize| -> Vec<u8> {
        (0..n)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                x as u8
            })
            .collect()
    };
    let real = forged_frame("local");
    let mut payloads: Vec<Vec<u8>> = vec![
        Vec::new(),
        real[..3].to_vec(),
        real[..real.len() / 2].to_vec(),
        proto::frame(&"not a request", b""),
        proto::frame(
            &Request::End {
                run_id: "0123456789abcdef".into(),
            },
            b"",
        ),
    ];
    for _ in 0..20 {
        let n = 1 + (noise(2)[0] as usize) * 8;
        payloads.push(noise(n));
    }
    let huge = vec![0u8; 64 << 20];
    let queried = [
        "formation/host/t1/req",
        "formation/host/t1/info",
        "formation/clock/t1",
        "formation/host/t1/other",
    ];
    let put_on: Vec<String> = ["to/t1", "to/local", "exit", "checkpoint"]
        .iter()
        .map(|k| format!("formation/run/{id}/{k}"))
        .collect();
    let mut sent = 0usize;
    // Resident memory after each round: it must not grow with the rounds.
    let mut rss_rounds = Vec::new();
    for _round in 0..3 {
        for key in &put_on {
            for pl in &payloads {
                p.put(key, pl.clone()).unwrap();
                sent += 1;
            }
            p.put(key, huge.clone()).unwrap();
            sent += 1;
        }
        for pl in &payloads {
            let _ = e.query(&export_info, Some(pl.clone()), Duration::from_millis(500));
            sent += 1;
        }
        let _ = e.query(&export_info, Some(huge.clone()), Duration::from_secs(5));
        sent += 1;
        let answers = e.query(&export_info, None, Duration::from_secs(5)).unwrap();
        assert!(
            answers
                .iter()
                .any(|a| a.as_ref().is_ok_and(|b| b.starts_with(b"{"))),
            "the export answers its info amid the fuzz"
        );
        for key in queried {
            for pl in &payloads {
                // Answers or not, the daemon must stay up; the answers are not checked here.
                let _ = p.query(key, Some(pl.clone()), Duration::from_millis(500));
                sent += 1;
            }
            let _ = p.query(key, Some(huge.clone()), Duration::from_secs(5));
            sent += 1;
        }
        rss_rounds.push(d.memory().0);
    }
    let log_during = d.log().lines().count();
    let (code, err_text) = finish(run, &err);
    assert_eq!(code, 0, "the fuzzed run failed:\n{err_text}");
    assert!(d.alive(), "the daemon is up:\n{}", d.log());
    // The daemon still answers.
    let info = p
        .query("formation/host/t1/info", None, Duration::from_secs(5))
        .unwrap();
    assert!(
        info.iter().any(|a| a
            .as_ref()
            .is_ok_and(|b| serde_json::from_slice::<proto::HostInfo>(b).is_ok())),
        "the daemon answers its info after the fuzz"
    );
    let (rss_after, rss_peak) = d.memory();
    // Bounded memory, however many messages came: each round sends the same (nine 64 MiB
    // messages among them) and the daemon's resident memory does not grow from round to round
    // (the allocator may keep what the first round freed: at most MEMORY_KEPT over before), and a
    // 64 MiB message is held a few times over at most (the peak within MEMORY_PEAK of before).
    const MIB: u64 = 1 << 20;
    const MEMORY_GROWTH: u64 = 32 * MIB;
    const MEMORY_KEPT: u64 = 160 * MIB;
    const MEMORY_PEAK: u64 = 640 * MIB;
    let mib: Vec<u64> = rss_rounds.iter().map(|r| r / MIB).collect();
    eprintln!(
        "daemon memory: {} MiB before the fuzz, {mib:?} MiB after each round, {} MiB after the run, {} MiB at its peak",
        rss_before / MIB,
        rss_after / MIB,
        rss_peak / MIB
    );
    assert!(
        rss_rounds[2] < rss_rounds[0] + MEMORY_GROWTH,
        "the daemon's memory grows with the fuzz: {mib:?} MiB after rounds 1-3"
    );
    assert!(
        rss_after < rss_before + MEMORY_KEPT,
        "the daemon kept the fuzz: {} MiB resident before, {} MiB after",
        rss_before / MIB,
        rss_after / MIB
    );
    assert!(
        rss_peak < rss_before + MEMORY_PEAK,
        "the daemon's memory peaked at {} MiB ({} MiB before the fuzz)",
        rss_peak / MIB,
        rss_before / MIB
    );
    // Bounded logs: a handful of lines per reason and second, not one per message.
    let log = d.log();
    let lines = log.lines().count();
    assert!(sent > 300, "the fuzz ran: {sent} messages");
    assert!(
        log_during < 60 && lines < 80,
        "{sent} hostile messages gave {lines} daemon log lines:\n{log}"
    );
    let run_lines = err_text.lines().count();
    assert!(
        run_lines < 60,
        "{sent} hostile messages gave {run_lines} lines on the orchestrator:\n{err_text}"
    );
    assert!(
        !log.contains("panicked") && !err_text.contains("panicked"),
        "no panic:\n{log}\n{err_text}"
    );
    formation_tests::assert_trajectory_is_sims(
        &out,
        &args.iter().map(String::as_str).collect::<Vec<_>>(),
        &dir.join("sim"),
    );
    let _ = std::fs::remove_dir_all(&dir);
}
