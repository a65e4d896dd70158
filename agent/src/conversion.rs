//! Command conversion of eq. (28): from the position control U_iP to the total thrust T_iC and the
//! attitude command (phi_iC, theta_iC) for a yaw command psi_iC.

/// Thrust (N) and attitude command [phi, theta, psi] (rad) for the acceleration command `u` (m/s²),
/// mass `m`, gravity `g`, yaw `psi`. Requires u_3 + g > 0 (Remark 3), which the limits of
/// [`crate::position`] guarantee.
pub fn thrust_and_attitude(u: [f64; 3], m: f64, g: f64, psi: f64) -> (f64, [f64; 3]) {
    let uz = u[2] + g;
    let norm = (u[0] * u[0] + u[1] * u[1] + uz * uz).sqrt();
    let thrust = m * norm;
    let (sp, cp) = psi.sin_cos();
    let phi = ((u[0] * sp - u[1] * cp) / norm).clamp(-1.0, 1.0).asin();
    let theta = ((u[0] * cp + u[1] * sp) / uz).atan();
    (thrust, [phi, theta, psi])
}
