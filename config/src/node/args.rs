//! Command line of the role processes, written by the orchestrator and parsed by the children.

use super::error::NodeError;
use std::path::PathBuf;

/// What a role process is told on its command line.
#[derive(Debug, Clone, PartialEq)]
pub struct ChildArgs {
    /// Run id (also part of the prefix); lets `ps` and tests find the processes of a run.
    pub run_id: String,
    /// iceoryx2 global prefix of the run.
    pub prefix: String,
    /// Run directory holding `scenario.toml`.
    pub run_dir: PathBuf,
    /// Controller variant name.
    pub variant: String,
    /// Agent index (0-based), for agents only.
    pub agent: Option<usize>,
    /// Realtime mode (wall-clock plant, real delays) instead of lockstep.
    pub realtime: bool,
    /// Realtime mode: how long the plant busy-polls before it blocks on its event, µs (0: block).
    pub spin_us: u32,
    /// Realtime mode: `SCHED_FIFO` priority of plant and agents (0: normal policy).
    pub rt_priority: u32,
    /// Agents: a new process taking over at this step (it rebuilds from `DIR/checkpoints/`).
    pub rejoin_at: Option<u64>,
    /// The run's membership lock to join instead of the one in the run directory
    /// ([`super::members`]): an agent started by a daemon that shares the orchestrator's
    /// `/dev/shm` joins the orchestrator's.
    pub members: Option<PathBuf>,
}

impl ChildArgs {
    /// The arguments, in the order [`ChildArgs::parse`] reads them.
    pub fn to_args(&self) -> Vec<std::ffi::OsString> {
        let mut v: Vec<std::ffi::OsString> = Vec::new();
        if let Some(i) = self.agent {
            v.push("--agent".into());
            v.push(i.to_string().into());
        }
        v.push("--run-id".into());
        v.push(self.run_id.clone().into());
        v.push("--prefix".into());
        v.push(self.prefix.clone().into());
        v.push("--variant".into());
        v.push(self.variant.clone().into());
        v.push("--run-dir".into());
        v.push(self.run_dir.clone().into_os_string());
        if let Some(r) = self.rejoin_at {
            v.push("--rejoin-at".into());
            v.push(r.to_string().into());
        }
        if let Some(m) = &self.members {
            v.push("--members".into());
            v.push(m.clone().into_os_string());
        }
        if self.realtime {
            v.push("--mode".into());
            v.push("realtime".into());
            v.push("--spin-us".into());
            v.push(self.spin_us.to_string().into());
            v.push("--rt-priority".into());
            v.push(self.rt_priority.to_string().into());
        }
        v
    }

    /// Parses `std::env::args_os()` minus the program name.
    pub fn parse(
        args: impl IntoIterator<Item = std::ffi::OsString>,
    ) -> Result<ChildArgs, NodeError> {
        let mut out = ChildArgs {
            run_id: String::new(),
            prefix: String::new(),
            run_dir: PathBuf::new(),
            variant: "proposed".into(),
            agent: None,
            realtime: false,
            spin_us: 0,
            rt_priority: 0,
            rejoin_at: None,
            members: None,
        };
        let mut it = args.into_iter();
        while let Some(flag) = it.next() {
            let flag = flag.to_string_lossy().into_owned();
            let value = it
                .next()
                .ok_or_else(|| NodeError::Args(format!("missing value after {flag}")))?;
            let text = value.to_string_lossy().into_owned();
            match flag.as_str() {
                "--agent" => {
                    out.agent =
                        Some(text.parse().map_err(|_| {
                            NodeError::Args(format!("--agent: not an index: {text}"))
                        })?)
                }
                "--rejoin-at" => {
                    out.rejoin_at =
                        Some(text.parse().map_err(|_| {
                            NodeError::Args(format!("--rejoin-at: not a step: {text}"))
                        })?)
                }
                "--run-id" => out.run_id = text,
                "--prefix" => out.prefix = text,
                "--variant" => out.variant = text,
                "--run-dir" => out.run_dir = PathBuf::from(value),
                "--members" => out.members = Some(PathBuf::from(value)),
                "--mode" => {
                    out.realtime = match text.as_str() {
                        "realtime" => true,
                        "lockstep" => false,
                        _ => {
                            return Err(NodeError::Args(format!(
                                "--mode: lockstep or realtime, not {text}"
                            )))
                        }
                    }
                }
                "--spin-us" => {
                    out.spin_us = text.parse().map_err(|_| {
                        NodeError::Args(format!("--spin-us: not a number of µs: {text}"))
                    })?
                }
                "--rt-priority" => {
                    out.rt_priority = text.parse().map_err(|_| {
                        NodeError::Args(format!("--rt-priority: not a priority: {text}"))
                    })?
                }
                _ => return Err(NodeError::Args(format!("unknown argument {flag}"))),
            }
        }
        if out.prefix.is_empty() || out.run_dir.as_os_str().is_empty() {
            return Err(NodeError::Args(
                "--prefix and --run-dir are required".into(),
            ));
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arguments_round_trip() {
        let a = ChildArgs {
            run_id: "abc".into(),
            prefix: "fmabc_".into(),
            run_dir: PathBuf::from("/tmp/x y"),
            variant: "no-rbfnn".into(),
            agent: Some(3),
            realtime: false,
            spin_us: 0,
            rt_priority: 0,
            rejoin_at: Some(20_500),
            members: None,
        };
        assert_eq!(ChildArgs::parse(a.to_args()).unwrap(), a);
        let joined = ChildArgs {
            members: Some(PathBuf::from("/out/run x/iox2/members.lock")),
            ..a.clone()
        };
        assert_eq!(ChildArgs::parse(joined.to_args()).unwrap(), joined);
        let rt = ChildArgs {
            realtime: true,
            spin_us: 20,
            rt_priority: 10,
            ..a
        };
        assert_eq!(ChildArgs::parse(rt.to_args()).unwrap(), rt);
        assert!(ChildArgs::parse(vec!["--bogus".into(), "1".into()]).is_err());
    }
}
