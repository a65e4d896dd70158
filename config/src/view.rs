//! What every view of a run draws alike — the Foxglove scene, the ROS 2 markers and the figures:
//! the agents' colours, the state of a graph edge at a step and its colour, and an attitude as a
//! quaternion; how a controller's separation layer is counted. Pure functions of the scenario's
//! and the messages' data.

use crate::scenario::events::Timeline;
use crate::Scenario;

/// The communication graph's edges as views draw them: 0-based pairs (a < b), sorted, each once.
pub fn edges(s: &Scenario) -> Vec<(usize, usize)> {
    let mut edges: Vec<(usize, usize)> = s
        .graph
        .edges
        .iter()
        .map(|e| {
            let (a, b) = (e.a - 1, e.b - 1);
            (a.min(b), a.max(b))
        })
        .collect();
    edges.sort_unstable();
    edges.dedup();
    edges
}

/// The agents (0-based) that receive the leader's reference (b_i > 0).
pub fn leader_links(s: &Scenario) -> Vec<usize> {
    (0..s.n_agents())
        .filter(|&i| s.graph.leader_weights.get(i).is_some_and(|&b| b > 0.0))
        .collect()
}

/// The agents' colours, cycled by id: a ten-colour qualitative palette (RGB, 0-255).
pub const AGENT_PALETTE: [[u8; 3]; 10] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
    [188, 189, 34],
    [23, 190, 207],
];

/// Colour of agent `id` (1-based; 0 counts as 1), RGB.
pub fn agent_rgb(id: usize) -> [u8; 3] {
    AGENT_PALETTE[(id.max(1) - 1) % AGENT_PALETTE.len()]
}

/// Colour of a quadrotor whose process is down, RGB.
pub const DOWN_RGB: [u8; 3] = [150, 150, 150];

/// The state of an edge of the communication graph at a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkState {
    /// Shares cross the edge both ways: green.
    Up,
    /// The edge is up but some share of this step does not cross it: an end's process is down
    /// (crash, hang) or a message-loss event drops it; the receiver works on older data. Amber.
    Stale,
    /// A `link_down` event cut the edge. Red.
    Down,
}

impl LinkState {
    /// The state of the edge {a, b} (0-based agents) at step k, from the run's timeline.
    pub fn at(timeline: &Timeline, a: usize, b: usize, k: u64) -> LinkState {
        if !timeline.link_up(a, b, k) {
            LinkState::Down
        } else if timeline.delivered(a, b, k) && timeline.delivered(b, a, k) {
            LinkState::Up
        } else {
            LinkState::Stale
        }
    }

    /// Its colour: RGB and opacity (0-1).
    pub fn rgba(self) -> ([u8; 3], f32) {
        match self {
            LinkState::Up => ([40, 170, 80], 0.9),
            LinkState::Stale => ([240, 170, 20], 0.95),
            LinkState::Down => ([220, 30, 30], 0.95),
        }
    }
}

/// The rotation of ZYX Euler angles A = [phi, theta, psi] (body to inertial, R = Rz Ry Rx as the
/// plant's eq. (1)) as a unit quaternion [x, y, z, w].
pub fn quaternion_xyzw(a: [f64; 3]) -> [f64; 4] {
    let (sr, cr) = (a[0] * 0.5).sin_cos();
    let (sp, cp) = (a[1] * 0.5).sin_cos();
    let (sy, cy) = (a[2] * 0.5).sin_cos();
    [
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_yaw_of_a_quarter_turn_is_a_rotation_about_z_and_zero_is_the_identity() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let q = quaternion_xyzw([0.0, 0.0, std::f64::consts::FRAC_PI_2]);
        for (got, want) in q.iter().zip([0.0, 0.0, h, h]) {
            assert!((got - want).abs() < 1e-12, "{q:?}");
        }
        assert_eq!(quaternion_xyzw([0.0; 3]), [0.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn the_paper_graph_has_each_edge_once_zero_based_and_one_agent_linked_to_the_leader() {
        let s = Scenario::paper();
        let e = edges(&s);
        assert!(e.windows(2).all(|w| w[0] < w[1]), "{e:?}");
        assert!(e.iter().all(|&(a, b)| a < b && b < s.n_agents()), "{e:?}");
        assert!(!leader_links(&s).is_empty());
    }

    #[test]
    fn agent_colours_cycle_after_ten_and_id_zero_is_agent_one() {
        assert_eq!(agent_rgb(1), agent_rgb(11));
        assert_eq!(agent_rgb(0), agent_rgb(1));
        assert_ne!(agent_rgb(1), agent_rgb(2));
    }
}

/// How long a controller's separation layer acted (D25) and the smallest separation it predicted,
/// counted alike in `summary.json` (every step of the run) and in live telemetry (every step of
/// one process).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeparationTally {
    /// Steps at which the layer changed the virtual control.
    pub active_steps: u64,
    /// Smallest predicted separation, m (infinite: none in range yet).
    pub min_predicted_m: f64,
}

impl Default for SeparationTally {
    fn default() -> SeparationTally {
        SeparationTally {
            active_steps: 0,
            min_predicted_m: f64::INFINITY,
        }
    }
}

impl SeparationTally {
    /// Counts the telemetry of one command.
    pub fn observe(&mut self, t: &crate::protocol::wire::ControllerTelemetry) {
        if t.sep_correction != [0.0; 3] {
            self.active_steps += 1;
        }
        self.min_predicted_m = self.min_predicted_m.min(t.sep_predicted_m);
    }

    /// Time the layer acted, s, for steps of `dt` s.
    pub fn active_s(&self, dt: f64) -> f64 {
        self.active_steps as f64 * dt
    }
}
