//! The links between hosts (docs/multi-host.md, "Endpoints and credentials"): a daemon's default
//! endpoint only its own user can reach, credentials required on every TCP endpoint, mutual TLS
//! whose refusals are named, and authentication failures reported as such, naming the host.
//!
//! The daemons here listen on loopback or on a Unix socket of the test's machine, each with its
//! own runtime folder (`XDG_RUNTIME_DIR`); no run starts on them. The test with a second uid
//! (65534) needs root: it skips elsewhere, unless `FORMATION_REQUIRE_ROOT=1` (set by `.ci/run`)
//! makes it required.

use formation_tests::host::{formation_rt, runtime, unique, Daemon};
use formation_tests::{bin, chown, root_or_skip, stderr_of, temp_dir, OTHER_UID};
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Command, Output};

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A UDP port of 127.0.0.1 free a moment ago (a `quic/` endpoint's).
fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn write_secret(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o600)).unwrap();
}

#[test]
fn a_wrong_password_is_reported_as_an_authentication_failure_naming_the_host() {
    let dir = temp_dir("transport-pw");
    let rt = runtime(&dir, 0o700);
    let (good, bad) = (dir.join("auth"), dir.join("wrong"));
    write_secret(&good, "formation:right-secret\n");
    write_secret(&bad, "formation:wrong-secret\n");
    let name = unique("pw");
    let ep = format!("tcp/127.0.0.1:{}", free_port());
    let s = |p: &Path| p.display().to_string();
    let _d = Daemon::start(
        &rt,
        &["--name", &name, "--listen", &ep, "--auth", &s(&good)],
    );
    // The right password: listed.
    let o = formation_rt(&rt, &["hosts", "--connect", &ep, "--auth", &s(&good)]);
    assert!(o.status.success(), "{}", stderr_of(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains(&name));
    // A wrong one: an authentication failure, naming the endpoint (and, for a run, the host).
    let o = formation_rt(&rt, &["hosts", "--connect", &ep, "--auth", &s(&bad)]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr_of(&o));
    let e = stderr_of(&o);
    assert!(
        e.contains(&ep) && e.contains("authentication failed"),
        "{e}"
    );
    let out = dir.join("run");
    let o = formation_rt(
        &rt,
        &[
            "run",
            "--set",
            "simulation.duration_s=1",
            "--hosts",
            &name,
            "--connect",
            &ep,
            "--auth",
            &s(&bad),
            "--out",
            &s(&out),
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr_of(&o));
    let e = stderr_of(&o);
    assert!(
        e.contains(&name) && e.contains(&ep) && e.contains("authentication failed"),
        "{e}"
    );
    // No credentials at all: refused before anything is sent, naming the option.
    let o = formation_rt(&rt, &["hosts", "--connect", &ep]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr_of(&o).contains("--auth FILE"), "{}", stderr_of(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn tcp_tls_and_quic_endpoints_without_credentials_are_refused_naming_the_option() {
    let dir = temp_dir("transport-opts");
    let rt = runtime(&dir, 0o700);
    for (args, option) in [
        (
            &["host", "--listen", "tcp/127.0.0.1:7447"][..],
            "--auth FILE",
        ),
        (&["host", "--listen", "tcp/0.0.0.0:7447"][..], "--auth FILE"),
        (&["host", "--listen", "tls/127.0.0.1:7447"][..], "--tls DIR"),
        (
            &["hosts", "--connect", "tls/127.0.0.1:7447"][..],
            "--tls DIR",
        ),
        (
            &["host", "--listen", "quic/127.0.0.1:7447"][..],
            "--tls DIR",
        ),
        (
            &["run", "--hosts", "b", "--connect", "quic/127.0.0.1:7447"][..],
            "--tls DIR",
        ),
        (
            &["run", "--hosts", "b", "--connect", "tcp/127.0.0.1:7447"][..],
            "--auth FILE",
        ),
    ] {
        let o = formation_rt(&rt, args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr_of(&o));
        assert!(
            stderr_of(&o).contains(option),
            "{args:?}: {}",
            stderr_of(&o)
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_certificate_of_another_ca_is_refused_and_named_either_way() {
    another_ca_is_refused_and_named("tls", free_port());
}

#[test]
fn a_certificate_of_another_ca_is_refused_and_named_either_way_over_quic() {
    another_ca_is_refused_and_named("quic", free_udp_port());
}

/// A daemon listening on `TRANSPORT/127.0.0.1:PORT` with certificates of one CA: listed with a
/// certificate of its CA, refused (exit 2, the endpoint and the reason named) by an orchestrator
/// of another CA, and refusing one that trusts its CA but presents a certificate of another.
fn another_ca_is_refused_and_named(transport: &str, port: u16) {
    let dir = temp_dir(&format!("transport-ca-{transport}"));
    let rt = runtime(&dir, 0o700);
    let s = |p: &Path| p.display().to_string();
    let certs = |args: &[&str]| {
        let o = formation_rt(&rt, &[&["certs"][..], args].concat());
        assert!(o.status.success(), "certs {args:?}: {}", stderr_of(&o));
    };
    let (ca1, ca2) = (dir.join("ca1"), dir.join("ca2"));
    certs(&["init", "--dir", &s(&ca1)]);
    certs(&["init", "--dir", &s(&ca2)]);
    let name = unique("tc");
    let (h, a, x) = (dir.join("h"), dir.join("a"), dir.join("x"));
    certs(&[
        "issue",
        "--dir",
        &s(&ca1),
        "--name",
        &name,
        "--addr",
        "127.0.0.1",
        "--out",
        &s(&h),
    ]);
    certs(&["issue", "--dir", &s(&ca1), "--name", "a", "--out", &s(&a)]);
    certs(&["issue", "--dir", &s(&ca2), "--name", "x", "--out", &s(&x)]);
    for f in ["ca.pem", "cert.pem", "key.pem"] {
        let m = std::fs::symlink_metadata(h.join(f)).unwrap().mode() & 0o777;
        assert_eq!(m, 0o600, "{f}");
    }
    assert_eq!(std::fs::metadata(&h).unwrap().mode() & 0o777, 0o700);
    assert_eq!(
        std::fs::metadata(ca1.join("ca.key")).unwrap().mode() & 0o777,
        0o600
    );
    // Trusting the daemon's CA with a certificate of another: the daemon refuses it.
    let mixed = dir.join("mixed");
    certs(&[
        "issue",
        "--dir",
        &s(&ca2),
        "--name",
        "m",
        "--out",
        &s(&mixed),
    ]);
    std::fs::remove_file(mixed.join("ca.pem")).unwrap();
    std::fs::copy(ca1.join("ca.pem"), mixed.join("ca.pem")).unwrap();
    let ep = format!("{transport}/127.0.0.1:{port}");
    let _d = Daemon::start(&rt, &["--name", &name, "--listen", &ep, "--tls", &s(&h)]);
    // Its own CA: listed.
    let o = formation_rt(&rt, &["hosts", "--connect", &ep, "--tls", &s(&a)]);
    assert!(o.status.success(), "{}", stderr_of(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains(&name));
    // A daemon whose certificate this host's CA did not sign: refused here, named.
    let o = formation_rt(&rt, &["hosts", "--connect", &ep, "--tls", &s(&x)]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr_of(&o));
    let e = stderr_of(&o);
    assert!(
        e.contains(&ep)
            && e.contains("authentication failed")
            && e.contains("not signed by the CA")
            && e.contains(&format!("CN={name}")),
        "{e}"
    );
    let out = dir.join("run");
    let run = |tls: &Path| {
        formation_rt(
            &rt,
            &[
                "run",
                "--set",
                "simulation.duration_s=1",
                "--hosts",
                &name,
                "--connect",
                &ep,
                "--tls",
                &s(tls),
                "--out",
                &s(&out),
            ],
        )
    };
    let o = run(&x);
    assert_eq!(o.status.code(), Some(2), "{}", stderr_of(&o));
    assert!(
        stderr_of(&o).contains("not signed by the CA"),
        "{}",
        stderr_of(&o)
    );
    // This host's certificate of another CA: the daemon refuses it, and that is said.
    let o = run(&mixed);
    assert_eq!(o.status.code(), Some(2), "{}", stderr_of(&o));
    let e = stderr_of(&o);
    assert!(
        e.contains(&ep) && e.contains("refused this host's certificate"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `formation ARGS` as uid/gid 65534, with its own runtime folder `rt`.
fn as_other(rt: &Path, args: &[&str]) -> Output {
    Command::new(bin("formation"))
        .args(args)
        .env("XDG_RUNTIME_DIR", rt)
        .env("HOME", rt)
        .env_remove("CARGO")
        .uid(OTHER_UID)
        .gid(OTHER_UID)
        .output()
        .expect("formation starts as uid 65534")
}

#[test]
fn an_unprivileged_user_cannot_reach_a_root_daemon_on_its_default_socket_nor_make_it_spawn() {
    if !root_or_skip(
        "an_unprivileged_user_cannot_reach_a_root_daemon_on_its_default_socket_nor_make_it_spawn",
    ) {
        return;
    }
    let dir = temp_dir("transport-uid");
    std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o755)).unwrap();
    // Root's runtime folder is open to others here (0755): what keeps them out is the daemon's
    // own folder in it.
    let rt = runtime(&dir, 0o755);
    let name = unique("tu");
    let d = Daemon::start(&rt, &["--name", &name]);
    let folder = rt.join("formation");
    let sock = folder.join(format!("{name}.sock"));
    let m = std::fs::symlink_metadata(&folder).unwrap();
    assert_eq!(
        (m.uid(), m.mode() & 0o777),
        (0, 0o700),
        "the socket's folder"
    );
    assert!(std::fs::symlink_metadata(&sock).is_ok(), "{}", d.log_text());
    // The owner drives it with no option at all; it listens on nothing but that socket.
    let o = formation_rt(&rt, &["hosts", "--json"]);
    assert!(o.status.success(), "{}", stderr_of(&o));
    let listed: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(listed[0]["name"], name.as_str());
    assert_eq!(
        listed[0]["listen"],
        serde_json::json!([format!("unixsock-stream/{}", sock.display())])
    );
    // uid 65534: its connect(2) is refused by the kernel, so it cannot list, prepare or spawn.
    let other_rt = dir.join("other-rt");
    std::fs::create_dir(&other_rt).unwrap();
    chown(&other_rt, OTHER_UID);
    let ep = format!("unixsock-stream/{}", sock.display());
    let o = as_other(&other_rt, &["hosts", "--connect", &ep]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr_of(&o));
    assert!(
        stderr_of(&o).contains("Permission denied"),
        "{}",
        stderr_of(&o)
    );
    let out = other_rt.join("run");
    let o = as_other(
        &other_rt,
        &[
            "run",
            "--set",
            "simulation.duration_s=1",
            "--hosts",
            &name,
            "--connect",
            &ep,
            "--out",
            &out.display().to_string(),
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr_of(&o));
    let e = stderr_of(&o);
    assert!(e.contains(&name) && e.contains("Permission denied"), "{e}");
    // Its own default finds no daemon of its own.
    let o = as_other(&other_rt, &["hosts"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr_of(&o).contains("no daemon of yours"),
        "{}",
        stderr_of(&o)
    );
    assert_eq!(d.children().trim(), "", "the daemon started nothing");
    assert!(!d.log_text().contains("spawn"), "{}", d.log_text());
    let _ = std::fs::remove_dir_all(&dir);
}
