//! References that arrive before their step (the leader runs up to `LEADER_LEAD` steps ahead),
//! held until the agent reaches that step: handing reference k to the agent only at step k keeps
//! its delay histories exactly those of the in-process run.
//!
//! A ring of preallocated frames indexed by step, filled with only the entries the agent reads
//! (its own and its neighbours', [`ReferenceFrame::copy_entries_from`]): a whole frame is ~9.3 kB,
//! its valid part N x 72 B, and copying either into a queue made an agent's memory traffic grow
//! with N (`perf record`: `memmove`, docs/runtime.md, "Cost of a step").

use formation_config::node::error::NodeError;
use formation_config::protocol::pacing::REFERENCE_BUFFER;
use formation_config::protocol::wire::ReferenceFrame;

/// The held references, steps `next..=newest`, contiguous.
pub struct EarlyReferences {
    slots: Vec<ReferenceFrame>,
    /// The entries kept of each frame (the agent's own and its neighbours'); every valid one if
    /// `None`.
    ids: Option<Vec<usize>>,
    /// Next step to hand to the agent.
    next: u64,
    /// Newest step held.
    newest: Option<u64>,
}

impl Default for EarlyReferences {
    fn default() -> Self {
        Self::with_capacity(REFERENCE_BUFFER)
    }
}

impl EarlyReferences {
    /// The ring of an agent that reads only the entries `ids` of each frame (its own and its
    /// neighbours'): only those are copied, whatever N.
    pub fn for_entries(ids: Vec<usize>) -> EarlyReferences {
        EarlyReferences {
            ids: Some(ids),
            ..Self::default()
        }
    }
}

impl EarlyReferences {
    /// Room for `capacity` steps (allocated once here).
    pub fn with_capacity(capacity: usize) -> EarlyReferences {
        EarlyReferences {
            slots: vec![ReferenceFrame::default(); capacity.max(1)],
            ids: None,
            next: 0,
            newest: None,
        }
    }

    /// Holds `r`; references must come in step order without gaps and fit in the ring.
    pub fn push(&mut self, r: &ReferenceFrame) -> Result<(), NodeError> {
        let expected = self.newest.map_or(self.next, |s| s + 1);
        if r.step != expected {
            return Err(NodeError::Protocol(format!(
                "protocol error: reference of step {} while expecting {expected}",
                r.step
            )));
        }
        let cap = self.slots.len() as u64;
        if r.step >= self.next + cap {
            return Err(NodeError::Protocol(format!(
                "protocol error: reference of step {} is more than {cap} steps ahead of step {}",
                r.step, self.next
            )));
        }
        let slot = &mut self.slots[(r.step % cap) as usize];
        match &self.ids {
            Some(ids) => slot.copy_entries_from(r, ids),
            None => slot.copy_valid_from(r),
        }
        self.newest = Some(r.step);
        Ok(())
    }

    /// True when the reference of `step` has not arrived yet.
    pub fn missing(&self, step: u64) -> bool {
        self.newest.is_none_or(|s| s < step)
    }

    /// Hands every held reference up to `step` to `f`, in step order, and forgets it.
    pub fn take_due(&mut self, step: u64, mut f: impl FnMut(&ReferenceFrame)) {
        let cap = self.slots.len() as u64;
        while self.next <= step && self.newest.is_some_and(|s| self.next <= s) {
            f(&self.slots[(self.next % cap) as usize]);
            self.next += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(step: u64) -> ReferenceFrame {
        let mut r = ReferenceFrame {
            step,
            t: step as f64 * 1e-3,
            n_agents: 2,
            ..ReferenceFrame::default()
        };
        r.p_d = [step as f64, 0.0, 1.0];
        r.offset[1] = [0.0, step as f64, 0.0];
        r
    }

    #[test]
    fn references_are_handed_over_in_order_only_when_their_step_comes() {
        let mut q = EarlyReferences::with_capacity(4);
        assert!(q.missing(0));
        for k in 0..3 {
            q.push(&frame(k)).unwrap();
        }
        assert!(!q.missing(2) && q.missing(3));
        let mut seen = Vec::new();
        q.take_due(1, |r| seen.push(*r));
        assert_eq!(seen, [frame(0), frame(1)]);
        q.take_due(1, |_| panic!("step 1 was handed over already"));
        for k in 3..6 {
            q.push(&frame(k)).unwrap();
        }
        seen.clear();
        q.take_due(9, |r| seen.push(*r));
        assert_eq!(seen, [frame(2), frame(3), frame(4), frame(5)]);
    }

    #[test]
    fn a_ring_for_some_entries_hands_over_the_header_and_exactly_those_entries() {
        let mut q = EarlyReferences::for_entries(vec![1, 3, 200]);
        let mut r = frame(0);
        r.n_agents = 4;
        for j in 0..4 {
            r.offset[j] = [j as f64; 3];
            r.offset_vel[j] = [10.0 + j as f64; 3];
            r.offset_acc[j] = [20.0 + j as f64; 3];
        }
        q.push(&r).unwrap();
        let mut seen = Vec::new();
        q.take_due(0, |h| seen.push(*h));
        let h = &seen[0];
        assert_eq!((h.step, h.t, h.n_agents, h.p_d), (r.step, r.t, 4, r.p_d));
        for j in [1, 3] {
            assert_eq!(
                (h.offset[j], h.offset_vel[j], h.offset_acc[j]),
                (r.offset[j], r.offset_vel[j], r.offset_acc[j])
            );
        }
        for j in [0, 2] {
            assert_eq!(h.offset[j], [0.0; 3], "entry {j} is not copied");
        }
    }

    #[test]
    fn a_gap_or_an_overflow_is_a_protocol_error() {
        let mut q = EarlyReferences::with_capacity(2);
        assert!(q.push(&frame(1)).is_err());
        q.push(&frame(0)).unwrap();
        q.push(&frame(1)).unwrap();
        assert!(q.push(&frame(2)).is_err());
    }
}
