//! Helpers for the end-to-end tests: locating the built binaries, temporary output directories.
#![warn(missing_docs)]

use std::path::PathBuf;

/// Path of the workspace binary `name` (e.g. `formation`) of the same profile as the running test.
///
/// Test executables live in `target/<profile>/deps/`; the binaries in `target/<profile>/`.
/// `cargo test --workspace` builds `formation` (the orchestrator package has integration tests), and
/// `formation` is the whole system: it starts its role processes from its own executable.
pub fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("the test executable has a path");
    let profile_dir = exe
        .parent()
        .and_then(|deps| deps.parent())
        .expect("the test executable lives in target/<profile>/deps/");
    let path = profile_dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    if !path.is_file() {
        panic!(
            "binary `{name}` not found at {}: run the tests with `cargo test --release --workspace`",
            path.display()
        );
    }
    path
}

/// A fresh empty directory under the system temporary directory, unique to this process and `tag`,
/// removed with everything in it when the test that made it passes (dropped without a panic); a
/// failing test leaves it for inspection.
pub fn temp_dir(tag: &str) -> TempDir {
    let dir = std::env::temp_dir().join(format!("formation-tests-{}-{tag}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("can create a temporary directory");
    TempDir(dir)
}

/// A test's directory ([`temp_dir`]): a path, removed on drop unless the thread is panicking.
#[derive(Debug)]
pub struct TempDir(PathBuf);

impl std::ops::Deref for TempDir {
    type Target = PathBuf;
    fn deref(&self) -> &PathBuf {
        &self.0
    }
}

impl AsRef<std::path::Path> for TempDir {
    fn as_ref(&self) -> &std::path::Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for TempDir {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// Runs `formation <args>` to its end, never building anything (no `CARGO` in its environment).
pub fn formation(args: &[&str]) -> std::process::Output {
    std::process::Command::new(bin("formation"))
        .args(args)
        .env_remove("CARGO")
        .output()
        .expect("formation starts")
}

/// What a finished command wrote on its standard error.
pub fn stderr_of(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The `summary.json` a run or sim wrote into `dir`.
pub fn summary(dir: &std::path::Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json is written");
    serde_json::from_str(&text).expect("summary.json parses")
}

/// Runs `formation <args>` to its end with the runs directory `runs` (`FORMATION_RUNS_DIR`), never
/// building anything (no `CARGO` in its environment).
pub fn formation_in(runs: &std::path::Path, args: &[&str]) -> std::process::Output {
    std::process::Command::new(bin("formation"))
        .env("FORMATION_RUNS_DIR", runs)
        .env_remove("CARGO")
        .args(args)
        .output()
        .expect("formation starts")
}

/// Runs `formation sim <args...> --out <out>` to its end (standard output discarded, never
/// building anything) and asserts that it succeeded.
pub fn sim(args: &[&str], out: &std::path::Path) {
    let st = std::process::Command::new(bin("formation"))
        .arg("sim")
        .args(args)
        .arg("--out")
        .arg(out)
        .env_remove("CARGO")
        .stdout(std::process::Stdio::null())
        .status()
        .expect("formation sim starts");
    assert!(st.success(), "formation sim failed");
}

/// CPUs in a `Cpus_allowed_list` line of /proc/<pid>/status (e.g. `0-1,3`).
pub fn cpus_allowed(pid: u32) -> Vec<usize> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    let list = status
        .lines()
        .find_map(|l| l.strip_prefix("Cpus_allowed_list:"))
        .unwrap_or("")
        .trim()
        .to_string();
    let mut out = Vec::new();
    for part in list.split(',').filter(|p| !p.is_empty()) {
        let (a, b) = part.split_once('-').unwrap_or((part, part));
        out.extend(a.parse::<usize>().unwrap()..=b.parse::<usize>().unwrap());
    }
    out
}

pub mod host;
pub mod run;
pub mod wire;

/// The workspace root (the parent of this crate's directory).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ lives in the workspace")
        .to_path_buf()
}

/// The Python interpreter with the iceoryx2 0.10 binding (`$FORMATION_PYTHON`, set by `.ci/run` to
/// its venv `target/pyenv`), or why there is none. Callers skip with the reason, unless
/// `FORMATION_REQUIRE_PYTHON=1` (set by `.ci/run`): then they must fail ([`python_or_skip`]).
pub fn python_with_iceoryx2() -> Result<PathBuf, String> {
    let py = std::env::var_os("FORMATION_PYTHON")
        .filter(|p| !p.is_empty())
        .map(PathBuf::from)
        .ok_or("FORMATION_PYTHON is not set (a Python with `pip install iceoryx2==0.10.0`)")?;
    let o = std::process::Command::new(&py)
        .args(["-c", "import iceoryx2"])
        .output()
        .map_err(|e| format!("cannot start {}: {e}", py.display()))?;
    if !o.status.success() {
        return Err(format!(
            "{} cannot import iceoryx2: {}",
            py.display(),
            String::from_utf8_lossy(&o.stderr).trim()
        ));
    }
    Ok(py)
}

/// `Some(interpreter)` from [`python_with_iceoryx2`]; `None` after printing why the calling test
/// is skipped; a panic instead when `FORMATION_REQUIRE_PYTHON=1`.
pub fn python_or_skip(test: &str) -> Option<PathBuf> {
    match python_with_iceoryx2() {
        Ok(py) => Some(py),
        Err(why) => skip_python_test(test, &why),
    }
}

/// A Python test cannot run (`why`): `None` after printing that it is skipped, or a panic when
/// `FORMATION_REQUIRE_PYTHON=1` (CI, which installs what the Python tests need).
pub fn skip_python_test<T>(test: &str, why: &str) -> Option<T> {
    if std::env::var("FORMATION_REQUIRE_PYTHON").as_deref() == Ok("1") {
        panic!("{test}: FORMATION_REQUIRE_PYTHON=1 but {why}");
    }
    eprintln!("{test}: skipped: {why}");
    None
}

/// Asserts that the run whose outputs are in `run_out` wrote byte for byte the `trajectory.csv`
/// of `formation sim` with the same `args` (written to `sim_out`).
pub fn assert_trajectory_is_sims(
    run_out: &std::path::Path,
    args: &[&str],
    sim_out: &std::path::Path,
) {
    let o = std::process::Command::new(bin("formation"))
        .arg("sim")
        .arg("--quiet")
        .args(args)
        .arg("--out")
        .arg(sim_out)
        .output()
        .expect("formation sim starts");
    assert!(
        o.status.success(),
        "formation sim failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let a = std::fs::read(run_out.join("trajectory.csv")).expect("the run's trajectory.csv");
    let b = std::fs::read(sim_out.join("trajectory.csv")).expect("sim's trajectory.csv");
    assert!(
        a == b,
        "trajectory.csv of the run in {} differs from formation sim's",
        run_out.display()
    );
}

/// The other user of the tests that act as a second uid (`nobody`).
pub const OTHER_UID: u32 = 65534;

/// Whether `test` may run: this process may use at least two CPUs. A machine with one skips it,
/// saying so, unless `FORMATION_REQUIRE_TWO_CPUS=1` (CI, which has two), where it fails.
pub fn two_cpus_or_skip(test: &str) -> bool {
    let n = cpus_allowed(std::process::id()).len();
    if n >= 2 {
        return true;
    }
    assert!(
        std::env::var("FORMATION_REQUIRE_TWO_CPUS").as_deref() != Ok("1"),
        "{test} needs two CPUs ({n} allowed) and FORMATION_REQUIRE_TWO_CPUS=1 requires it"
    );
    eprintln!("skipping {test}: it needs two CPUs, this process may use {n}");
    false
}

/// True when the test can act as another uid ([`OTHER_UID`]): it runs as root. Otherwise says
/// why `test` skips, or fails when CI requires it with `FORMATION_REQUIRE_ROOT=1`.
pub fn root_or_skip(test: &str) -> bool {
    // SAFETY: getuid has no preconditions.
    if unsafe { libc::getuid() } == 0 {
        return true;
    }
    assert!(
        std::env::var("FORMATION_REQUIRE_ROOT").as_deref() != Ok("1"),
        "{test} needs root (to act as uid {OTHER_UID}) and FORMATION_REQUIRE_ROOT=1 requires it"
    );
    eprintln!("skipping {test}: it needs root to own files and run processes as uid {OTHER_UID}");
    false
}

/// Gives `path` (not followed if a link) to `uid` (user and group).
pub fn chown(path: &std::path::Path, uid: u32) {
    let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: lchown on a valid C string path.
    assert_eq!(unsafe { libc::lchown(c.as_ptr(), uid, uid) }, 0, "chown");
}

/// Waits until the `formation host` daemon `child`, whose standard error goes to `log`, says it
/// is `listening on` its endpoints (at most `limit`). Panics naming `what` with the daemon's log
/// when it exits first or does not listen in time.
pub fn wait_until_listening(
    child: &mut std::process::Child,
    log: &std::path::Path,
    what: &str,
    limit: std::time::Duration,
) {
    let t0 = std::time::Instant::now();
    let text = || std::fs::read_to_string(log).unwrap_or_default();
    while !text().contains("listening on") {
        if let Ok(Some(st)) = child.try_wait() {
            panic!("{what} exited ({st}) before listening: {}", text());
        }
        assert!(t0.elapsed() < limit, "{what} did not listen: {}", text());
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// A fresh empty folder `<group>/<pid>-<tag>` beside the built binaries, outside /tmp: tests
/// whose daemons run in mount namespaces with a /tmp of their own need a folder both sides see.
pub fn work_dir_beside_binaries(group: &str, tag: &str) -> PathBuf {
    let d = bin("formation")
        .parent()
        .expect("a binary lives in a folder")
        .join(group)
        .join(format!("{}-{tag}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("can create a folder beside the binaries");
    d
}

/// Runs `ip ARGS` (iproute2), panicking with its error text when it fails: the network-namespace
/// tests build their links with it.
pub fn ip(args: &[&str]) {
    let o = std::process::Command::new("ip")
        .args(args)
        .output()
        .expect("ip runs");
    assert!(
        o.status.success(),
        "ip {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&o.stderr)
    );
}
