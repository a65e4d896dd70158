//! The recorded states and commands of the last steps of every quadrotor: what a new agent
//! process rebuilds its controller from (`formation_agent::restart`). The in-process runner and
//! the orchestrator keep the same ring.

use formation_config::protocol::wire::VehicleState;
use formation_config::scenario::events::{Runtime, Timeline};

/// A ring of the states and commands of the last `len` steps of N quadrotors.
pub struct History {
    n: usize,
    len: u64,
    /// Steps recorded so far (the ring holds [newest - len, newest)).
    newest: u64,
    states: Vec<VehicleState>,
    commands: Vec<(f64, [f64; 3])>,
}

impl History {
    /// Room for `len` steps of `n` quadrotors (0: keeps nothing).
    pub fn new(n: usize, len: u64) -> History {
        let cells = if len == 0 { 0 } else { n * len as usize };
        History {
            n,
            len,
            newest: 0,
            states: vec![VehicleState::default(); cells],
            commands: vec![(0.0, [0.0; 3]); cells],
        }
    }

    /// Steps it holds (0: it keeps nothing).
    pub fn len(&self) -> u64 {
        self.len
    }

    /// True when it keeps nothing (a loop without down windows).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    fn slot(&self, k: u64, i: usize) -> usize {
        (k % self.len.max(1)) as usize * self.n + i
    }

    /// The oldest step still held.
    pub fn oldest(&self) -> u64 {
        self.newest.saturating_sub(self.len)
    }

    /// Stores quadrotor i's state of step k.
    pub fn set_state(&mut self, k: u64, i: usize, s: VehicleState) {
        let slot = self.slot(k, i);
        self.states[slot] = s;
        self.newest = self.newest.max(k + 1);
    }

    /// Stores agent i's (thrust, torque) command of step k.
    pub fn set_command(&mut self, k: u64, i: usize, c: (f64, [f64; 3])) {
        let slot = self.slot(k, i);
        self.commands[slot] = c;
    }

    /// Quadrotor j's state at step k (held).
    pub fn state(&self, k: u64, j: usize) -> VehicleState {
        self.states[self.slot(k, j)]
    }

    /// Agent i's command at step k (held).
    pub fn command(&self, k: u64, i: usize) -> (f64, [f64; 3]) {
        self.commands[self.slot(k, i)]
    }
}

/// The longest down window of a timeline that can be replayed, steps (0: none): only a window
/// whose new process takes over before the run's `n_steps` end is ever rebuilt, so a longer one
/// (validation bounds `down_s` by the run's remaining time) sizes nothing.
pub fn longest_down(t: &Timeline, n_steps: u64) -> u64 {
    t.down_windows()
        .iter()
        .filter(|w| w.to < n_steps)
        .map(|w| w.to.saturating_sub(w.from))
        .max()
        .unwrap_or(0)
}

/// Steps of history a restart may read: a checkpoint period, the longest down window and the
/// delay histories of `capacity` steps, with slack.
pub fn len(runtime: &Runtime, dt: f64, capacity: usize, longest_down: u64) -> u64 {
    runtime.checkpoint_steps(dt) + longest_down + capacity as u64 + 8
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_config::scenario::events::{Event, EventKind};

    #[test]
    fn a_down_window_that_never_rejoins_inside_the_run_sizes_no_history() {
        let dt = 0.001;
        let crash = |at: f64, down: f64| {
            let mut e = Event::new(at, EventKind::Crash);
            e.agent = Some(1);
            e.down_s = Some(down);
            e
        };
        let n_steps = 10_000;
        let t = Timeline::new(&[crash(1.0, 0.5), crash(2.0, 1e9)], dt);
        assert_eq!(longest_down(&t, n_steps), 500);
        let t = Timeline::new(&[crash(2.0, 8.0)], dt);
        assert_eq!(
            longest_down(&t, n_steps),
            0,
            "rejoins at the end: never replayed"
        );
    }
}
