//! Lumped position uncertainty F_iP (61), attitude disturbance D_iA (62) and model perturbation
//! Delta F_i of eq. (2).

use crate::memo::{Direct, Math};
use formation_config::scenario::{DisturbanceSpec, ModelPerturbationSpec, UncertaintySpec};
use nalgebra::{Matrix3, Vector3};

/// Eq. (61): f_ik = gain_k sin(c_k P_ik + V_ik^p_k).
pub fn uncertainty(u: &UncertaintySpec, p: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    let mut f = Vector3::zeros();
    for k in 0..3 {
        let vk = if u.velocity_power[k] == 2 {
            v[k] * v[k]
        } else {
            v[k]
        };
        f[k] = u.gain[k] * (u.position_coeff[k] * p[k] + vk).sin();
    }
    f
}

/// Eq. (62): the magnitude ||D_iA(t)|| applied along the unit direction of the spec, rad/s².
pub fn disturbance(d: &DisturbanceSpec, t: f64) -> Vector3<f64> {
    disturbance_with(d, t, &mut Direct)
}

/// [`disturbance`] with exp, sin and cos from `f` (a plant's [`crate::memo::Memo`]).
pub fn disturbance_with(d: &DisturbanceSpec, t: f64, f: &mut impl Math) -> Vector3<f64> {
    let chirp = f.exp(d.chirp_growth * t) * t + d.chirp_phase_rad;
    let m = d.slow_amplitude * f.sin(t + d.slow_phase_rad)
        + d.chirp_amplitude * f.cos(chirp)
        + d.fast_amplitude * f.cos(d.fast_rate_rad_s * t + d.fast_phase_rad)
        + d.bias;
    let dir = Vector3::from(d.direction);
    dir * (m / dir.norm())
}

/// Delta F_i(t) = I + diag(a_k sin(w t + p_k)) (our reading, docs/deviations.md D9).
pub fn model_perturbation(m: &ModelPerturbationSpec, t: f64) -> Matrix3<f64> {
    model_perturbation_with(m, t, &mut Direct)
}

/// [`model_perturbation`] with sin from `f` (a plant's [`crate::memo::Memo`]).
pub fn model_perturbation_with(
    m: &ModelPerturbationSpec,
    t: f64,
    f: &mut impl Math,
) -> Matrix3<f64> {
    let mut out = Matrix3::identity();
    for k in 0..3 {
        out[(k, k)] += m.amplitude[k] * f.sin(m.rate_rad_s * t + m.phase_rad[k]);
    }
    out
}
