//! Rotation matrices of eq. (1)-(2).

use nalgebra::{Matrix3, Vector3};

/// R_t of eq. (1): body-to-inertial rotation, ZYX Euler angles A = [phi, theta, psi].
/// The printed (3,3) entry c_theta s_phi is a slip for c_theta c_phi (errata).
pub fn rotation(a: &Vector3<f64>) -> Matrix3<f64> {
    let (sf, cf) = a[0].sin_cos();
    let (st, ct) = a[1].sin_cos();
    let (sp, cp) = a[2].sin_cos();
    Matrix3::new(
        ct * cp,
        st * cp * sf - sp * cf,
        st * cp * cf + sp * sf,
        ct * sp,
        st * sp * sf + cp * cf,
        st * sp * cf - cp * sf,
        -st,
        ct * sf,
        ct * cf,
    )
}

/// Third column of R_t (the thrust direction R_t e_3), without building the whole matrix.
pub fn thrust_axis(a: &Vector3<f64>) -> Vector3<f64> {
    let (sf, cf) = a[0].sin_cos();
    let (st, ct) = a[1].sin_cos();
    let (sp, cp) = a[2].sin_cos();
    Vector3::new(st * cp * cf + sp * sf, st * sp * cf - cp * sf, ct * cf)
}

/// R_r of eq. (2): body rates to Euler-angle rates, A' = R_r Omega. Singular at theta = +-pi/2.
pub fn euler_rate_matrix(a: &Vector3<f64>) -> Matrix3<f64> {
    let (sf, cf) = a[0].sin_cos();
    let (st, ct) = a[1].sin_cos();
    let tt = st / ct;
    Matrix3::new(1.0, sf * tt, cf * tt, 0.0, cf, -sf, 0.0, sf / ct, cf / ct)
}

/// S(Omega): the skew matrix with S(a) b = a x b.
pub fn skew(w: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -w[2], w[1], w[2], 0.0, -w[0], -w[1], w[0], 0.0)
}
