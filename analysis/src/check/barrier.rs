//! Barrier feasibility (errata): the attitude must stay within C_i1 (the attitude margin) of the
//! command the AFTAC tracks, so what the filtered attitude command can demand (command filter 1's
//! rate limit and bandwidth) must fit the roll/pitch angular acceleration the actuators still deliver
//! after the worst faults (63)-(64) and the disturbance (62).

use formation_config::Scenario;
use formation_plant::faults::FaultModel;
use serde::Serialize;

/// Authority against demand on roll and pitch.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Barrier {
    /// Smallest torque the actuators can still deliver in both directions on roll/pitch, over agents
    /// and time, when the command U_iAC is clipped to [U_L, U_H]: min(Gamma U_H + delta, U_H) and
    /// min(-(Gamma U_L + delta), -U_L), N m (about Gamma_ik |U_max| - |delta_ik|).
    pub torque_authority_nm: f64,
    /// Agent and axis (1-based) of the smallest authority.
    pub authority_at: [usize; 2],
    /// Time of the smallest authority, s.
    pub authority_time_s: f64,
    /// The same torque over the inertia J_k, rad/s².
    pub accel_authority_rad_s2: f64,
    /// Largest attitude disturbance (62) magnitude over agents (sum of the amplitudes and the bias),
    /// taken as acting fully on that axis, rad/s².
    pub disturbance_bound_rad_s2: f64,
    /// Authority left after the disturbance, rad/s².
    pub net_accel_authority_rad_s2: f64,
    /// Rate limit R of command filter 1 on roll/pitch (largest of the two), rad/s.
    pub command_rate_limit_rad_s: f64,
    /// R omega_B: the acceleration scale of the filtered command, rad/s².
    pub command_accel_estimate_rad_s2: f64,
    /// 2 xi_B omega_B R: the filtered command's peak acceleration when its rate limit engages from
    /// rest (q2' = 2 xi w (S_R(.) - q2)), rad/s².
    pub command_accel_peak_rad_s2: f64,
    /// Attitude margin C_i1, rad.
    pub attitude_margin_rad: f64,
    /// Angular-rate constraint C-bar_i2, rad/s.
    pub rate_constraint_rad_s: f64,
    /// Fastest command rate the vehicle can follow inside the barrier: min(C-bar_i2,
    /// sqrt(2 a C_i1)) with a the net authority (reaching rate R at acceleration a lags the command
    /// by R² / (2 a), which must stay below C_i1), rad/s.
    pub followable_rate_rad_s: f64,
}

/// Time step of the scan of the fault profiles, s.
const SCAN_DT_S: f64 = 0.01;

/// Torque available in both directions for fault (gamma, delta) and limits [lo, hi], with the
/// command clipped to the limits.
pub fn torque_authority(gamma: f64, delta: f64, lo: f64, hi: f64) -> f64 {
    let up = (gamma * hi + delta).min(hi);
    let down = (-(gamma * lo + delta)).min(-lo);
    up.min(down)
}

/// Bound of the disturbance magnitude (62) of one agent.
fn disturbance_bound(a: &formation_config::scenario::AgentSpec) -> f64 {
    let d = &a.disturbance;
    d.slow_amplitude.abs() + d.chirp_amplitude.abs() + d.fast_amplitude.abs() + d.bias.abs()
}

/// Scans the fault profiles of every agent over the run and compares with the command filter.
pub fn analyse(s: &Scenario) -> Barrier {
    let v = &s.vehicle;
    let (mut best, mut at, mut time, mut accel) = (f64::INFINITY, [0, 0], 0.0, f64::INFINITY);
    let steps = (s.simulation.duration_s / SCAN_DT_S).ceil().clamp(1.0, 1e6) as u64;
    for (i, a) in s.agents.iter().enumerate() {
        let faults = FaultModel::new(&a.fault);
        for n in 0..=steps {
            let t = n as f64 * SCAN_DT_S;
            let (g, d) = faults.at(0, t);
            for k in 0..2 {
                let u = torque_authority(g[k], d[k], v.torque_min_nm[k], v.torque_max_nm[k]);
                let acc = u / v.inertia_kg_m2[k];
                if acc < accel {
                    (best, at, time, accel) = (u, [i + 1, k + 1], t, acc);
                }
            }
        }
    }
    let dist = s.agents.iter().map(disturbance_bound).fold(0.0, f64::max);
    let net = accel - dist;
    let f = &s.controller.attitude_command_filter;
    let rate = f.rate_limit[0].max(f.rate_limit[1]);
    let att = &s.controller.attitude;
    let followable = if net > 0.0 {
        (2.0 * net * att.attitude_margin_rad)
            .sqrt()
            .min(att.rate_limit_rad_s)
    } else {
        0.0
    };
    Barrier {
        torque_authority_nm: best,
        authority_at: at,
        authority_time_s: time,
        accel_authority_rad_s2: accel,
        disturbance_bound_rad_s2: dist,
        net_accel_authority_rad_s2: net,
        command_rate_limit_rad_s: rate,
        command_accel_estimate_rad_s2: rate * f.natural_frequency_rad_s,
        command_accel_peak_rad_s2: 2.0 * f.damping * f.natural_frequency_rad_s * rate,
        attitude_margin_rad: att.attitude_margin_rad,
        rate_constraint_rad_s: att.rate_limit_rad_s,
        followable_rate_rad_s: followable,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn authority_is_gamma_times_limit_minus_additive_fault() {
        assert!((torque_authority(0.73, -0.15, -0.4, 0.4) - (0.73 * 0.4 - 0.15)).abs() < 1e-12);
        // A healthy actuator keeps the whole limit.
        assert!((torque_authority(1.0, 0.0, -0.4, 0.4) - 0.4).abs() < 1e-12);
        // A fault pushing beyond the limit leaves nothing against it.
        assert!(torque_authority(1.0, 0.5, -0.4, 0.4) < 0.0);
    }

    #[test]
    fn paper_faults_leave_about_a_third_of_the_roll_pitch_torque() {
        let b = analyse(&Scenario::paper_exact());
        // Agent 4 roll: Gamma 0.73, delta -0.15 after the ramp: 0.292 - 0.15 = 0.142 N m.
        assert!(
            (b.torque_authority_nm - 0.142).abs() < 2e-3,
            "{}",
            b.torque_authority_nm
        );
        assert_eq!(b.authority_at, [4, 1]);
        assert!((b.accel_authority_rad_s2 - b.torque_authority_nm / 0.02351).abs() < 1e-9);
        // The filtered command can ask for far more than that.
        assert!(b.command_accel_estimate_rad_s2 > b.net_accel_authority_rad_s2);
        assert!(b.followable_rate_rad_s < b.command_rate_limit_rad_s);
    }
}
