//! History buffer keyed by simulation step: agent i reads information stamped t - tau_i(t).

/// A ring of (step, value) pairs with a capacity fixed at construction.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct StepHistory<T: Copy> {
    slots: Vec<Option<(u64, T)>>,
    newest: Option<u64>,
}

impl<T: Copy> StepHistory<T> {
    /// A history that remembers the last `capacity` steps.
    pub fn new(capacity: usize) -> StepHistory<T> {
        StepHistory {
            slots: vec![None; capacity.max(1)],
            newest: None,
        }
    }

    /// Number of steps remembered.
    pub fn capacity(&self) -> usize {
        self.slots.len()
    }

    /// Stores the value of `step` (overwrites the slot of step - capacity).
    pub fn push(&mut self, step: u64, value: T) {
        let n = self.slots.len() as u64;
        self.slots[(step % n) as usize] = Some((step, value));
        self.newest = Some(self.newest.map_or(step, |s| s.max(step)));
    }

    /// Newest step stored.
    pub fn newest(&self) -> Option<u64> {
        self.newest
    }

    /// True when the value of exactly `step` is stored.
    pub fn has(&self, step: u64) -> bool {
        let n = self.slots.len() as u64;
        matches!(self.slots[(step % n) as usize], Some((s, _)) if s == step)
    }

    /// The value of `step`; if it is missing, the newest value stamped before it; if there is none, the
    /// oldest value held. `None` only when the history is empty.
    pub fn at_or_before(&self, step: u64) -> Option<T> {
        self.entry_at_or_before(step).map(|(_, v)| v)
    }

    /// The step of the value [`StepHistory::at_or_before`] returns.
    pub fn step_at_or_before(&self, step: u64) -> Option<u64> {
        self.entry_at_or_before(step).map(|(s, _)| s)
    }

    fn entry_at_or_before(&self, step: u64) -> Option<(u64, T)> {
        let n = self.slots.len() as u64;
        if let Some((s, v)) = self.slots[(step % n) as usize] {
            if s == step {
                return Some((s, v));
            }
        }
        let mut best: Option<(u64, T)> = None;
        let mut oldest: Option<(u64, T)> = None;
        for (s, v) in self.slots.iter().flatten() {
            if *s <= step && best.is_none_or(|(b, _)| *s > b) {
                best = Some((*s, *v));
            }
            if oldest.is_none_or(|(o, _)| *s < o) {
                oldest = Some((*s, *v));
            }
        }
        best.or(oldest)
    }
}

/// Delay in whole steps for a delay `tau` (s) and step `dt` (s): round(tau / dt), at least 0.
pub fn delay_steps(tau: f64, dt: f64) -> u64 {
    if tau.is_finite() && tau > 0.0 {
        (tau / dt).round() as u64
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_step_of_the_value_used_is_the_newest_at_or_before_and_the_value_is_unchanged() {
        let mut h = StepHistory::new(8);
        assert_eq!(h.step_at_or_before(5), None);
        for s in [3u64, 4, 7] {
            h.push(s, s as f64 * 10.0);
        }
        assert_eq!(h.step_at_or_before(7), Some(7));
        assert_eq!(h.step_at_or_before(6), Some(4), "6 missing: 4 stands in");
        assert_eq!(h.at_or_before(6), Some(40.0));
        assert_eq!(
            h.step_at_or_before(1),
            Some(3),
            "nothing before: the oldest held"
        );
    }
}
