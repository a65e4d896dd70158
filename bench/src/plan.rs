//! What one bench run measures: the list of cases (transport x pattern x waiting strategy x CPU
//! placement) and the cases it skips, with the reason.

use super::link::Wait;
use std::time::Duration;

/// How the messages travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    /// iceoryx2 publish-subscribe, woken by an event listener (blocking `timed_wait`).
    IoxEvent,
    /// iceoryx2 publish-subscribe, woken through a WaitSet the event listener is attached to.
    IoxWaitSet,
    /// iceoryx2 publish-subscribe, busy-polled (no events).
    IoxPoll,
    /// Unix domain datagram sockets (abstract namespace).
    Uds,
    /// UDP on 127.0.0.1.
    Udp,
    /// Zenoh over loopback (TCP or TLS), with the sessions and frames of a run across hosts (measured by
    /// `bench::zenoh` and `bench::split`, never planned here; only when named in `--transports`).
    Zenoh,
}

impl Transport {
    /// Every transport, in report order.
    pub const ALL: [Transport; 6] = [
        Transport::IoxEvent,
        Transport::IoxWaitSet,
        Transport::IoxPoll,
        Transport::Uds,
        Transport::Udp,
        Transport::Zenoh,
    ];

    /// Name used in the report and on the peer command line.
    pub fn name(self) -> &'static str {
        match self {
            Transport::IoxEvent => "iox2-event",
            Transport::IoxWaitSet => "iox2-waitset",
            Transport::IoxPoll => "iox2-poll",
            Transport::Uds => "uds-dgram",
            Transport::Udp => "udp",
            Transport::Zenoh => "zenoh",
        }
    }

    /// Inverse of [`Transport::name`].
    pub fn parse(s: &str) -> Option<Transport> {
        Transport::ALL.into_iter().find(|t| t.name() == s)
    }
}

/// Message pattern of a case.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pattern {
    /// Plant sends, one agent replies: a full round trip per sample.
    PingPong,
    /// Plant publishes a step to N agents, each replies, plant waits for all N: one step per sample.
    FanOut,
}

impl Pattern {
    /// Name used in the report.
    pub fn name(self) -> &'static str {
        match self {
            Pattern::PingPong => "ping-pong",
            Pattern::FanOut => "fan-out",
        }
    }
}

/// Where the processes of a case run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Placement {
    /// Wherever the scheduler puts them.
    Free,
    /// Every process on this one CPU.
    OneCore(usize),
    /// Process k (plant = 0, agent i = i + 1) on CPU `list[k % len]`.
    RoundRobin(Vec<usize>),
}

impl Placement {
    /// CPU of process `k`, if pinned.
    pub fn cpu_of(&self, k: usize) -> Option<usize> {
        match self {
            Placement::Free => None,
            Placement::OneCore(c) => Some(*c),
            Placement::RoundRobin(list) => list.get(k % list.len().max(1)).copied(),
        }
    }

    fn suffix(&self) -> &'static str {
        match self {
            Placement::Free => "",
            Placement::OneCore(_) => "/one-core",
            Placement::RoundRobin(_) => "/pinned",
        }
    }
}

/// One measured case.
#[derive(Debug, Clone)]
pub struct Case {
    /// Transport.
    pub transport: Transport,
    /// Pattern.
    pub pattern: Pattern,
    /// Number of agent processes (1 for ping-pong).
    pub n: usize,
    /// Waiting strategy of every process.
    pub wait: Wait,
    /// CPU placement.
    pub placement: Placement,
    /// Every process of the case under `SCHED_BATCH` (woken processes do not preempt).
    pub batch: bool,
}

impl Case {
    /// Waiting strategy and placement as shown in the report (`block`, `spin-block`, `busy`, with
    /// `/one-core` or `/pinned` when the processes are pinned).
    pub fn wait_label(&self) -> String {
        let w = match self.wait {
            Wait::Block => "block",
            Wait::SpinBlock(_) => "spin-block",
            Wait::Busy => "busy",
        };
        let policy = if self.batch { "/batch" } else { "" };
        format!("{w}{}{policy}", self.placement.suffix())
    }
}

/// Inputs of the plan.
pub struct PlanInput {
    /// Agents of the fan-out cases.
    pub n: usize,
    /// Spin budget of spin-then-block.
    pub spin: Duration,
    /// CPUs from `--cpu` (round-robin pinning), or `None` for unpinned.
    pub cpus: Option<Vec<usize>>,
    /// CPUs this process may use.
    pub allowed: Vec<usize>,
    /// Transports to include (all if empty).
    pub only: Vec<Transport>,
    /// Also time a real lockstep `formation run` with `n` agents.
    pub lockstep: bool,
}

/// The cases to run, and the skipped ones as (description, reason).
pub fn plan(input: &PlanInput) -> (Vec<Case>, Vec<(String, String)>) {
    let base = match &input.cpus {
        Some(list) => Placement::RoundRobin(list.clone()),
        None => Placement::Free,
    };
    let cores = match &input.cpus {
        Some(list) => list.len(),
        None => input.allowed.len(),
    };
    let one = input
        .cpus
        .as_ref()
        .and_then(|l| l.first().copied())
        .or_else(|| input.allowed.first().copied())
        .unwrap_or(0);
    let wanted = |t: Transport| input.only.is_empty() || input.only.contains(&t);
    let mut cases = Vec::new();
    let mut skipped = Vec::new();
    for (pattern, n) in [(Pattern::PingPong, 1), (Pattern::FanOut, input.n)] {
        for t in [
            Transport::IoxEvent,
            Transport::IoxWaitSet,
            Transport::Uds,
            Transport::Udp,
        ] {
            if !wanted(t) {
                continue;
            }
            for (wait, placement, batch) in [
                (Wait::Block, base.clone(), false),
                (Wait::SpinBlock(input.spin), base.clone(), false),
                (Wait::Block, Placement::OneCore(one), false),
                // SCHED_BATCH matters when processes outnumber cores: the fan-out only.
                (Wait::Block, base.clone(), true),
            ] {
                if batch && pattern != Pattern::FanOut {
                    continue;
                }
                cases.push(Case {
                    transport: t,
                    pattern,
                    n,
                    wait,
                    placement,
                    batch,
                });
            }
        }
        // The lockstep run pins plant and agents round-robin over the allowed CPUs under
        // SCHED_BATCH (`formation run --pin always`): its like-for-like baseline is the iceoryx2
        // event fan-out placed and scheduled the same way (already in the list with `--cpu`).
        if pattern == Pattern::FanOut
            && input.lockstep
            && wanted(Transport::IoxEvent)
            && input.cpus.is_none()
            && input.allowed.len() >= 2
        {
            cases.push(Case {
                transport: Transport::IoxEvent,
                pattern,
                n,
                wait: Wait::Block,
                placement: Placement::RoundRobin(input.allowed.clone()),
                batch: true,
            });
        }
        if wanted(Transport::IoxPoll) {
            let procs = n + 1;
            if procs <= cores {
                cases.push(Case {
                    transport: Transport::IoxPoll,
                    pattern,
                    n,
                    wait: Wait::Busy,
                    placement: base.clone(),
                    batch: false,
                });
            } else {
                skipped.push((
                    format!("{} {} n={n}", Transport::IoxPoll.name(), pattern.name()),
                    format!(
                        "{procs} busy-polling processes on {cores} cores: spinners preempt each \
                         other for whole time slices (milliseconds per step)"
                    ),
                ));
            }
        }
    }
    (cases, skipped)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn input(n: usize, cpus: Option<Vec<usize>>) -> PlanInput {
        PlanInput {
            n,
            spin: Duration::from_micros(50),
            cpus,
            allowed: vec![0, 1],
            only: vec![],
            lockstep: false,
        }
    }

    #[test]
    fn busy_poll_fan_out_is_skipped_when_processes_outnumber_cores() {
        let (cases, skipped) = plan(&input(5, None));
        assert!(cases
            .iter()
            .any(|c| c.transport == Transport::IoxPoll && c.pattern == Pattern::PingPong));
        assert!(!cases
            .iter()
            .any(|c| c.transport == Transport::IoxPoll && c.pattern == Pattern::FanOut));
        assert_eq!(skipped.len(), 1);
    }

    #[test]
    fn cpu_list_pins_round_robin_and_one_core_uses_its_first_cpu() {
        let (cases, _) = plan(&input(2, Some(vec![1, 0])));
        let pinned = cases
            .iter()
            .find(|c| c.wait_label() == "block/pinned")
            .unwrap();
        assert_eq!(pinned.placement.cpu_of(0), Some(1));
        assert_eq!(pinned.placement.cpu_of(1), Some(0));
        assert_eq!(pinned.placement.cpu_of(2), Some(1));
        let one = cases
            .iter()
            .find(|c| c.wait_label() == "block/one-core")
            .unwrap();
        assert_eq!(one.placement.cpu_of(2), Some(1));
    }

    #[test]
    fn with_the_lockstep_the_fan_out_is_also_measured_placed_like_the_lockstep() {
        let mut i = input(5, None);
        i.allowed = vec![0, 1];
        i.lockstep = true;
        let (cases, _) = plan(&i);
        let like = cases
            .iter()
            .find(|c| c.wait_label() == "block/pinned/batch")
            .expect("the like-for-like fan-out");
        assert_eq!(like.transport, Transport::IoxEvent);
        assert_eq!(like.pattern, Pattern::FanOut);
        let cpus: Vec<_> = (0..6).map(|k| like.placement.cpu_of(k)).collect();
        assert_eq!(cpus, [0, 1, 0, 1, 0, 1].map(Some));
        i.lockstep = false;
        assert!(plan(&i)
            .0
            .iter()
            .all(|c| c.wait_label() != "block/pinned/batch"));
    }

    #[test]
    fn batch_policy_is_measured_for_fan_out_only() {
        let (cases, _) = plan(&input(5, None));
        assert!(cases
            .iter()
            .any(|c| c.batch && c.pattern == Pattern::FanOut && c.wait_label() == "block/batch"));
        assert!(!cases
            .iter()
            .any(|c| c.batch && c.pattern == Pattern::PingPong));
    }
}
