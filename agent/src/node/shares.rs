//! Reading the neighbours' shares in lockstep. Each neighbour publishes one share per step, and
//! none publishes its share of step k + 1 before this agent's command of step k is in (the plant
//! sends the states of k + 1 only once every command of k is in). At step k the queue of a
//! neighbour therefore holds at most its shares up to k, and the controller of step k needs a
//! share of step k only when a delay rounds to zero steps.
//!
//! So at step k each neighbour is read up to its share of k - 1 and no further: once that share
//! is in, a further `receive` would find at most the share of k, which stays queued (at most one
//! sample, far below the subscriber buffer) and is read at step k + 1. On the usual wake-up
//! (the plant's, with the state of k) this is one `receive` per neighbour, which returns the share
//! of k - 1, instead of two (the second finding nothing or the share of k). Only when the
//! controller is not ready are the queues read to the end ([`Shares::read_all`]).
//!
//! The controller's inputs are unchanged: it keys every share by its step and uses at step k only
//! shares of its delayed step k_d <= k; the share of k, when it is needed, is read before the
//! controller runs (`Agent::ready` is false without it).

use crate::Agent;
use formation_config::node::error::NodeError;
use formation_config::node::ports::Input;
use formation_config::protocol::wire::NeighbourState;

/// The newest share step read from each neighbour (in `neighbours` order).
pub struct Shares {
    newest: Vec<Option<u64>>,
}

impl Shares {
    /// Nothing read yet from any of `neighbours` neighbours.
    pub fn new(neighbours: usize) -> Shares {
        Shares {
            newest: vec![None; neighbours],
        }
    }

    /// At step k, reads each neighbour's queue until its share of k - 1 is in (or the queue is
    /// empty), handing every share to `agent`.
    pub fn read_due(
        &mut self,
        subs: &[Input<NeighbourState>],
        k: u64,
        agent: &mut Agent,
    ) -> Result<(), NodeError> {
        self.read(subs, agent, |newest| wants_more(newest, k))
    }

    /// Reads every queued share (the controller of the current step is not ready: it may need a
    /// share of this very step).
    pub fn read_all(
        &mut self,
        subs: &[Input<NeighbourState>],
        agent: &mut Agent,
    ) -> Result<(), NodeError> {
        self.read(subs, agent, |_| true)
    }

    fn read(
        &mut self,
        subs: &[Input<NeighbourState>],
        agent: &mut Agent,
        more: impl Fn(Option<u64>) -> bool,
    ) -> Result<(), NodeError> {
        for (sub, newest) in subs.iter().zip(self.newest.iter_mut()) {
            while more(*newest) {
                let Some(s) = sub.receive()? else { break };
                *newest = Some(newest.map_or(s.step, |n| n.max(s.step)));
                agent.observe_neighbour(&s);
            }
        }
        Ok(())
    }
}

/// Whether a neighbour whose newest share read is of step `newest` is read again at step `k`:
/// until its share of k - 1 is in (at step 0, until its first share).
fn wants_more(newest: Option<u64>, k: u64) -> bool {
    newest.is_none_or(|s| s.saturating_add(1) < k)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_neighbour_is_read_until_its_share_of_the_previous_step_is_in() {
        assert!(wants_more(None, 7), "nothing read yet");
        assert!(wants_more(Some(5), 7), "share of k - 2 only");
        assert!(!wants_more(Some(6), 7), "share of k - 1 in");
        assert!(!wants_more(Some(7), 7), "share of k in");
    }

    #[test]
    fn at_step_zero_a_neighbour_is_read_until_its_first_share() {
        assert!(wants_more(None, 0));
        assert!(!wants_more(Some(0), 0));
        assert!(wants_more(None, 1));
        assert!(!wants_more(Some(0), 1));
    }
}
