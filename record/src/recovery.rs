//! How the formation came through each event of the timeline (`summary.json` `events`,
//! `connectivity`; docs/failures.md): the per-step formation error (worst agent) and constraint
//! violations are kept for the whole run, and each event is measured against them at the end.
//!
//! * `recovered_after_s`: sim time from the event to the first step from which the formation
//!   error (worst agent) stays under max(0.3 m, 2x its worst value in the second before the event)
//!   for `SETTLE_S` (for a `crash` or `hang`, through `SETTLE_S` after the controller's return), searched within the event's window (until the next event of the same agent,
//!   or 30 s); 0 if it never left; null if it does not settle within the window.
//! * `peak_error_m`: the worst formation error from the event to its recovery and the `SETTLE_S`
//!   that confirm it (or the window's end); `violations_during`: attitude and rate constraint
//!   violations (all agents) over the same span.
//! * for an event that takes an agent down (`crash`, `hang`): `min_separation_during_m` and
//!   `steps_below_safety_during`, the closest approach of two quadrotors and the steps below the
//!   safety distance from the event to the later of the span's end and the controller's return;
//!   `violations_once_back`, the constraint violations (all agents) from the controller's return
//!   to the later of the span's end and `SETTLE_S` after the return.
//! * `connectivity`: whether Assumption 1 (the graph of the agents that are up, over the links
//!   that are up, connected, and one of them pinned to the leader) held at every step.

use formation_config::protocol::messages::RuntimeEvent;
use formation_config::scenario::events::{Event, Timeline};
use formation_config::scenario::graph::Topology;
use serde::Serialize;

/// Lowest recovery threshold, m.
pub const RECOVERY_FLOOR_M: f64 = 0.3;
/// The threshold is this many times the worst error in the second before the event.
pub const RECOVERY_FACTOR: f64 = 2.0;
/// The second before an event, s.
pub const BEFORE_S: f64 = 1.0;
/// Longest window an event is followed for, s.
pub const WINDOW_S: f64 = 30.0;
/// How long the error must stay under the threshold to count as recovered, s.
pub const SETTLE_S: f64 = 2.0;

/// One event as measured (`summary.json` `events[]`).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct EventSummary {
    /// `fault`, `delay`, `crash`, `hang`, `link_down`, `link_up`, `message_loss`, or a detected
    /// `died` / `hung` / `host_lost`.
    pub kind: String,
    /// The agent (1-based), if one.
    pub agent: Option<usize>,
    /// The edge (1-based), for link events.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub agents: Option<[usize; 2]>,
    /// `host_lost`: the host the agent was lost with (it was taken over on the launcher).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub host: Option<String>,
    /// Sim time of the event, s.
    pub at_s: f64,
    /// Detected death or stall: wall ms from the last time the process was seen working.
    pub detected_after_ms: Option<f64>,
    /// Wall ms from the kill or detection to the new process's hello.
    pub restarted_after_ms: Option<f64>,
    /// Sim time until the formation error is back under its threshold, s.
    pub recovered_after_s: Option<f64>,
    /// The threshold, m.
    pub recovery_threshold_m: f64,
    /// Worst formation error in the event's window, m.
    pub peak_error_m: f64,
    /// Constraint violations from the event to its recovery.
    pub violations_during: u64,
    /// Closest approach of two quadrotors from the event to the later of its span's end and the
    /// controller's return, m (events that take an agent down).
    pub min_separation_during_m: Option<f64>,
    /// Steps below the safety distance over the same span.
    pub steps_below_safety_during: Option<u64>,
    /// Constraint violations from the controller's return to the later of the span's end and
    /// `SETTLE_S` after the return.
    pub violations_once_back: Option<u64>,
}

/// Whether Assumption 1 held (`summary.json` `connectivity`).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Connectivity {
    /// True when it held at every step.
    pub assumption1_held: bool,
    /// Steps at which it did not.
    pub steps_violated: u64,
    /// First and last such step's time, s.
    pub first_violated_at_s: Option<f64>,
    /// Last such step's time, s.
    pub last_violated_at_s: Option<f64>,
}

/// An event to measure: what, who, when, and what the supervision saw (run only).
#[derive(Debug, Clone, PartialEq)]
pub struct Mark {
    /// Its kind's name.
    pub kind: String,
    /// Agent (0-based).
    pub agent: Option<usize>,
    /// Edge (0-based).
    pub agents: Option<[usize; 2]>,
    /// Its step.
    pub step: u64,
    /// Detection delay, ms.
    pub detected_after_ms: Option<f64>,
    /// Restart time, ms.
    pub restarted_after_ms: Option<f64>,
    /// The step its controller is back (events that take an agent down for a known time).
    pub back_step: Option<u64>,
    /// The host lost with the agent (`host_lost`).
    pub host: Option<String>,
}

impl Mark {
    /// The mark of a timeline event.
    pub fn of_event(e: &Event, dt: f64) -> Mark {
        let one = |a: Option<usize>| a.map(|a| a.saturating_sub(1));
        Mark {
            kind: e.kind.name().to_string(),
            agent: one(e.agent).or(one(e.from)),
            agents: e.agents.map(|[a, b]| [a - 1, b - 1]),
            step: e.step(dt),
            detected_after_ms: None,
            restarted_after_ms: None,
            back_step: e
                .down_s
                .filter(|_| e.kind.takes_agent_down())
                .map(|d| e.step(dt).saturating_add((d / dt).round().max(1.0) as u64)),
            host: None,
        }
    }
}

/// The per-step series of a run.
#[derive(Debug, Default)]
pub struct Series {
    /// Worst agent's formation error per step, m.
    pub error: Vec<f64>,
    /// Cumulative constraint violations (all agents) after each step.
    pub violations: Vec<u64>,
    /// Closest distance of two quadrotors per step, m (empty: not recorded).
    pub separation: Vec<f64>,
    /// Safety distance, m.
    pub safety_m: f64,
}

impl Series {
    /// Room for `steps` steps; closer than `safety_m` (m) counts as below the safety distance.
    pub fn with_capacity(steps: usize, safety_m: f64) -> Series {
        Series {
            error: Vec::with_capacity(steps),
            violations: Vec::with_capacity(steps),
            separation: Vec::with_capacity(steps),
            safety_m,
        }
    }

    /// Appends one step.
    pub fn push(&mut self, error: f64, violations: u64) {
        self.error.push(error);
        self.violations.push(violations);
    }

    /// Appends one step's closest distance of two quadrotors (after [`Series::push`]).
    pub fn push_separation(&mut self, d: f64) {
        self.separation.push(d);
    }

    /// Measures each mark (sorted by step) against the series.
    pub fn measure(&self, marks: &[Mark], dt: f64) -> Vec<EventSummary> {
        let steps = self.error.len() as u64;
        let before = (BEFORE_S / dt).round() as u64;
        let window = (WINDOW_S / dt).round() as u64;
        let mut out = Vec::with_capacity(marks.len());
        for (idx, m) in marks.iter().enumerate() {
            let s = m.step.min(steps);
            let pre = &self.error[s.saturating_sub(before) as usize..s as usize];
            let pre_worst = pre.iter().copied().fold(0.0, f64::max);
            let threshold = RECOVERY_FLOOR_M.max(RECOVERY_FACTOR * pre_worst);
            let next_same = marks[idx + 1..]
                .iter()
                .find(|n| n.agent.is_some() && n.agent == m.agent && n.step > m.step)
                .map_or(u64::MAX, |n| n.step);
            let end = steps.min(s.saturating_add(window)).min(next_same);
            let settle = (SETTLE_S / dt).round() as usize;
            let span = &self.error[s as usize..end as usize];
            // An event that takes a controller down is recovered only once the error has also
            // stayed under through SETTLE_S after the controller's return.
            let must_reach = m.back_step.map_or(0, |b| b.saturating_add(settle as u64)) as usize;
            // The first step from which `settle` steps (or the rest of the run) stay under.
            let mut recovered: Option<u64> = None;
            let mut run_start = 0usize;
            for (p, &e) in span.iter().enumerate() {
                let at = s as usize + p + 1;
                if e > threshold {
                    run_start = p + 1;
                } else if (p + 1 - run_start >= settle && at >= must_reach) || at == steps as usize
                {
                    recovered = Some(s + run_start as u64);
                    break;
                }
            }
            let recovered_step = recovered.unwrap_or(end);
            // The event's span: to its recovery and through the settling that confirmed it (and
            // through SETTLE_S after the controller's return).
            let span_end = (recovered_step + settle as u64)
                .max(must_reach as u64)
                .min(end)
                .max(s);
            let peak = self.error[s as usize..span_end as usize]
                .iter()
                .copied()
                .fold(0.0, f64::max);
            let viol = |k: u64| {
                k.checked_sub(1)
                    .and_then(|k| self.violations.get(k as usize))
                    .copied()
                    .unwrap_or(0)
            };
            let back = m.back_step.map(|b| b.min(steps));
            let sep_span =
                back.map(|b| s as usize..(span_end.max(b) as usize).min(self.separation.len()));
            let sep = sep_span.map(|r| self.separation.get(r).unwrap_or(&[]));
            let back_end = back.map(|b| span_end.max(b + settle as u64).min(steps));
            out.push(EventSummary {
                min_separation_during_m: sep.and_then(|d| d.iter().copied().reduce(f64::min)),
                steps_below_safety_during: sep
                    .map(|d| d.iter().filter(|&&x| x < self.safety_m).count() as u64),
                violations_once_back: back
                    .zip(back_end)
                    .map(|(b, e)| viol(e).saturating_sub(viol(b))),
                kind: m.kind.clone(),
                agent: m.agent.map(|a| a + 1),
                agents: m.agents.map(|[a, b]| [a + 1, b + 1]),
                host: m.host.clone(),
                at_s: m.step as f64 * dt,
                detected_after_ms: m.detected_after_ms,
                restarted_after_ms: m.restarted_after_ms,
                recovered_after_s: recovered.map(|r| (r - s) as f64 * dt),
                recovery_threshold_m: threshold,
                peak_error_m: peak,
                violations_during: viol(span_end).saturating_sub(viol(s)),
            });
        }
        out
    }
}

/// Whether Assumption 1 holds at step k on `timeline`: the agents that are up, over the links
/// that are up, form a connected graph with at least one of them pinned (b_i > 0).
pub fn assumption1(topology: &Topology, timeline: &Timeline, k: u64, seen: &mut Vec<bool>) -> bool {
    let n = topology.n();
    seen.clear();
    seen.resize(n, false);
    let Some(start) = (0..n).find(|&i| timeline.up(i, k)) else {
        return false;
    };
    let mut stack = vec![start];
    seen[start] = true;
    while let Some(i) = stack.pop() {
        for &(j, _) in &topology.neighbours[i] {
            if !seen[j] && timeline.up(j, k) && timeline.link_up(i, j, k) {
                seen[j] = true;
                stack.push(j);
            }
        }
    }
    let connected = (0..n).all(|i| seen[i] || !timeline.up(i, k));
    connected && (0..n).any(|i| timeline.up(i, k) && topology.leader_weights[i] > 0.0)
}

/// Assumption 1 over a run of `steps` steps (only computed when the timeline can break it).
pub fn connectivity(topology: &Topology, timeline: &Timeline, steps: u64, dt: f64) -> Connectivity {
    let mut seen = Vec::new();
    let mut violated = 0;
    let mut first = None;
    let mut last = None;
    if !timeline.is_empty() {
        for k in 0..steps {
            if !assumption1(topology, timeline, k, &mut seen) {
                violated += 1;
                first.get_or_insert(k as f64 * dt);
                last = Some(k as f64 * dt);
            }
        }
    }
    Connectivity {
        assumption1_held: violated == 0,
        steps_violated: violated,
        first_violated_at_s: first,
        last_violated_at_s: last,
    }
}

/// The marks of a run: the scenario's events, the runtime events (live crashes, hangs, links,
/// losses), and the supervision's incidents, sorted by step, then agent (two agents lost with one
/// host are detected in whichever order the supervision polls them).
pub fn marks(events: &[Event], runtime: &[RuntimeEvent], incidents: &[Mark], dt: f64) -> Vec<Mark> {
    let mut out: Vec<Mark> = events.iter().map(|e| Mark::of_event(e, dt)).collect();
    out.extend(
        runtime
            .iter()
            .filter_map(|r| r.to_event(dt))
            .map(|e| Mark::of_event(&e, dt)),
    );
    for inc in incidents {
        // A timeline crash or hang is already there: it gets the supervision's times.
        match out
            .iter_mut()
            .find(|m| m.kind == inc.kind && m.agent == inc.agent && m.step == inc.step)
        {
            Some(m) => {
                m.detected_after_ms = inc.detected_after_ms;
                m.restarted_after_ms = inc.restarted_after_ms;
            }
            None => out.push(inc.clone()),
        }
    }
    out.sort_by_key(|m| (m.step, m.agent));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_config::scenario::events::EventKind;

    #[test]
    fn an_event_recovers_when_the_error_is_back_under_twice_its_value_before_and_stays_there() {
        let mut s = Series::default();
        for k in 0..3000u64 {
            let e = match k {
                0..1000 => 0.1,
                1000..1500 => 1.0,
                _ => 0.15,
            };
            s.push(
                e,
                if (1000..1200).contains(&k) {
                    k - 999
                } else if k >= 1200 {
                    201
                } else {
                    0
                },
            );
            s.push_separation(if (1050..1060).contains(&k) { 0.4 } else { 1.0 });
        }
        s.safety_m = 0.5;
        let m = Mark {
            kind: "crash".into(),
            agent: Some(2),
            agents: None,
            step: 1000,
            detected_after_ms: None,
            restarted_after_ms: Some(80.0),
            back_step: Some(1100),
            host: None,
        };
        let out = s.measure(&[m], 0.001);
        let e = &out[0];
        assert_eq!(e.recovery_threshold_m, 0.3, "floor: 2 x 0.1 < 0.3");
        assert!((e.recovered_after_s.unwrap() - 0.5).abs() < 1e-9);
        assert_eq!(e.peak_error_m, 1.0);
        assert!(
            s.measure(
                &[Mark {
                    step: 2000,
                    ..out_mark()
                }],
                0.001
            )[0]
            .recovered_after_s
                == Some(0.0),
            "never above its threshold, 2 x the 1.0 m of the second before"
        );
        assert_eq!(e.violations_during, 201);
        assert_eq!(e.min_separation_during_m, Some(0.4));
        assert_eq!(e.steps_below_safety_during, Some(10));
        assert_eq!(
            e.violations_once_back,
            Some(101),
            "from the return at step 1100: 201 - 100"
        );
        assert!(e.peak_error_m >= 0.15);
        assert_eq!(e.agent, Some(3));
    }

    #[test]
    fn a_down_controller_is_recovered_only_once_the_error_stays_under_after_its_return() {
        let mut s = Series::default();
        // Under the threshold through the 2 s down window, then a bump 1 s after the return.
        for k in 0..10_000u64 {
            s.push(if (3000..3500).contains(&k) { 1.0 } else { 0.1 }, 0);
            s.push_separation(1.0);
        }
        let m = Mark {
            kind: "crash".into(),
            agent: Some(0),
            agents: None,
            step: 0,
            detected_after_ms: None,
            restarted_after_ms: None,
            back_step: Some(2000),
            host: None,
        };
        let e = &s.measure(&[m], 0.001)[0];
        assert_eq!(
            e.peak_error_m, 1.0,
            "the bump after the return is the event's"
        );
        assert!((e.recovered_after_s.unwrap() - 3.5).abs() < 1e-9, "{e:?}");
    }

    #[test]
    fn assumption1_breaks_when_a_path_loses_an_inner_link_and_holds_again_after() {
        let mut s = formation_config::Scenario::paper();
        let mut d = Event::new(1.0, EventKind::LinkDown);
        d.agents = Some([2, 3]);
        let mut u = Event::new(2.0, EventKind::LinkUp);
        u.agents = Some([2, 3]);
        s.events = vec![d, u];
        let c = connectivity(&Topology::from_scenario(&s), &s.timeline(), 3000, 0.001);
        assert!(!c.assumption1_held);
        assert_eq!(c.steps_violated, 1000);
        assert_eq!(c.first_violated_at_s, Some(1.0));
    }

    fn out_mark() -> Mark {
        Mark {
            kind: "fault".into(),
            agent: None,
            agents: None,
            step: 0,
            detected_after_ms: None,
            restarted_after_ms: None,
            back_step: None,
            host: None,
        }
    }
}
