//! The input of the scene: what one step of a run looked like ([`Frame`]), built from the step
//! records every runner hands its recorder, or from the rows of `trajectory.csv`.

use formation_config::protocol::wire::{ControlCommand, PlantTruth};
use formation_config::Scenario;

/// One agent at one step: what the scene draws and the telemetry channels carry.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AgentSample {
    /// Position P_i (inertial frame, z up), m.
    pub position: [f64; 3],
    /// Attitude A_i = [phi, theta, psi] (ZYX Euler angles, eq. (1)), rad.
    pub attitude: [f64; 3],
    /// Formation error |P_i - P_d - Delta_i0|, m.
    pub formation_error_m: f64,
    /// Gamma-hat_i (diagonal), eq. (48).
    pub gamma_hat: [f64; 3],
    /// delta-hat_i, eq. (47), N m.
    pub delta_hat: [f64; 3],
    /// True multiplicative fault Gamma_i (diagonal).
    pub gamma: [f64; 3],
    /// True additive fault delta_i, N m.
    pub delta: [f64; 3],
    /// Attitude constraint margin C_i1bar - |A_i| with C_i1bar = |A_iC| + margin (negative: a
    /// violation, as counted in `summary.json`), rad.
    pub attitude_margin_rad: f64,
    /// Rate constraint margin C_i2bar - |Omega_i|, rad/s.
    pub rate_margin_rad_s: f64,
    /// Delay tau_i(t_k) the agent applied, s.
    pub tau_s: f64,
}

/// One step of a run, as the scene sees it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Frame {
    /// Simulation step k.
    pub step: u64,
    /// Simulation time t_k = k dt, s.
    pub t: f64,
    /// Virtual leader P_d, m.
    pub p_d: [f64; 3],
    /// Ground target T_g, m.
    pub target: [f64; 3],
    /// Slots P_d + Delta_i0 of agents 1..N, m.
    pub slots: Vec<[f64; 3]>,
    /// Agents 1..N.
    pub agents: Vec<AgentSample>,
}

/// The constraint limits that turn a state into margins (`[controller.attitude]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Attitude margin over the command's norm, rad (`attitude_margin_rad`).
    pub attitude_margin_rad: f64,
    /// Rate limit C_i2bar, rad/s (`rate_limit_rad_s`).
    pub rate_limit_rad_s: f64,
}

impl Limits {
    /// The limits of a scenario.
    pub fn of(s: &Scenario) -> Limits {
        Limits {
            attitude_margin_rad: s.controller.attitude.attitude_margin_rad,
            rate_limit_rad_s: s.controller.attitude.rate_limit_rad_s,
        }
    }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// The records of one step as a recorder receives them, borrowed: the input of
/// [`Frame::from_records`].
#[derive(Debug, Clone, Copy)]
pub struct StepRecords<'a> {
    /// Simulation step k.
    pub step: u64,
    /// Simulation time t_k = k dt, s.
    pub t: f64,
    /// Virtual leader P_d, m.
    pub p_d: [f64; 3],
    /// Ground target T_g, m.
    pub target: [f64; 3],
    /// Formation offsets Delta_i0 of the N agents, m.
    pub offsets: &'a [[f64; 3]],
    /// The plant's truths of the N agents.
    pub truths: &'a [PlantTruth],
    /// The N commands.
    pub commands: &'a [ControlCommand],
    /// Formation error of each agent, m.
    pub errors: &'a [f64],
}

impl Frame {
    /// The frame of one step from the records a recorder receives: the reference (P_d, T_g,
    /// Delta_i0), the plant's truths, the commands and the formation errors of the N agents.
    /// Margins are computed with the same operations as `summary.json`'s.
    pub fn from_records(r: StepRecords<'_>, limits: Limits) -> Frame {
        let StepRecords {
            step,
            t,
            p_d,
            target,
            offsets,
            truths,
            commands,
            errors,
        } = r;
        let slots = offsets
            .iter()
            .map(|o| [p_d[0] + o[0], p_d[1] + o[1], p_d[2] + o[2]])
            .collect();
        let agents = truths
            .iter()
            .zip(commands)
            .zip(errors)
            .map(|((tr, cmd), &e)| {
                let st = &tr.state;
                let tm = &cmd.telemetry;
                let c1_bar = norm(tm.attitude_cmd) + limits.attitude_margin_rad;
                AgentSample {
                    position: st.position,
                    attitude: st.attitude,
                    formation_error_m: e,
                    gamma_hat: tm.gamma_hat,
                    delta_hat: tm.delta_hat,
                    gamma: tr.gamma,
                    delta: tr.delta,
                    attitude_margin_rad: c1_bar - norm(st.attitude),
                    rate_margin_rad_s: limits.rate_limit_rad_s - norm(st.rate),
                    tau_s: tm.tau_s,
                }
            })
            .collect();
        Frame {
            step,
            t,
            p_d,
            target,
            slots,
            agents,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_from_records_has_the_slots_and_the_margins_of_the_summary() {
        let mut truth = PlantTruth::default();
        truth.state.position = [1.0, 2.0, 3.0];
        truth.state.attitude = [0.3, 0.4, 0.0];
        truth.state.rate = [0.0, 0.6, 0.8];
        let mut cmd = ControlCommand::default();
        cmd.telemetry.attitude_cmd = [0.0, 0.0, 0.2];
        cmd.telemetry.gamma_hat = [0.9, 0.8, 0.7];
        let limits = Limits {
            attitude_margin_rad: 0.5,
            rate_limit_rad_s: 3.0,
        };
        let f = Frame::from_records(
            StepRecords {
                step: 7,
                t: 0.007,
                p_d: [10.0, 0.0, 5.0],
                target: [1.0, 1.0, 0.0],
                offsets: &[[1.0, -1.0, 0.0]],
                truths: &[truth],
                commands: &[cmd],
                errors: &[0.25],
            },
            limits,
        );
        assert_eq!(f.slots, vec![[11.0, -1.0, 5.0]]);
        let a = f.agents[0];
        assert_eq!(a.position, [1.0, 2.0, 3.0]);
        assert_eq!(a.formation_error_m, 0.25);
        assert_eq!(a.gamma_hat, [0.9, 0.8, 0.7]);
        // |A| = 0.5, |A_C| + margin = 0.7; |Omega| = 1, limit 3.
        assert!((a.attitude_margin_rad - 0.2).abs() < 1e-12);
        assert!((a.rate_margin_rad_s - 2.0).abs() < 1e-12);
    }
}
