//! The quadrotor's kinematics of eq. (1)-(2): rotation matrices, Euler-angle rates and the
//! rotational drift, shared by the plant (which integrates them) and the controller (its nominal
//! model).

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

/// Sines and cosines of an attitude, computed once for the several matrices that need them.
#[derive(Debug, Clone, Copy)]
pub struct AttitudeTrig {
    sf: f64,
    cf: f64,
    st: f64,
    ct: f64,
    sp: f64,
    cp: f64,
}

impl AttitudeTrig {
    /// The trigonometric values of A = [phi, theta, psi].
    pub fn of(a: &Vector3<f64>) -> AttitudeTrig {
        let (sf, cf) = a[0].sin_cos();
        let (st, ct) = a[1].sin_cos();
        let (sp, cp) = a[2].sin_cos();
        AttitudeTrig {
            sf,
            cf,
            st,
            ct,
            sp,
            cp,
        }
    }

    /// Third column of R_t (the thrust direction R_t e_3).
    pub fn thrust_axis(&self) -> Vector3<f64> {
        let AttitudeTrig {
            sf,
            cf,
            st,
            ct,
            sp,
            cp,
        } = *self;
        Vector3::new(st * cp * cf + sp * sf, st * sp * cf - cp * sf, ct * cf)
    }

    /// R_r Omega of eq. (2) (Euler-angle rates), without building R_r.
    pub fn euler_rates(&self, w: &Vector3<f64>) -> Vector3<f64> {
        let AttitudeTrig { sf, cf, st, ct, .. } = *self;
        let tt = st / ct;
        let (qs, rc) = (sf * w[1], cf * w[2]);
        Vector3::new(w[0] + (qs + rc) * tt, cf * w[1] - sf * w[2], (qs + rc) / ct)
    }

    /// R_r of eq. (2). Singular at theta = +-pi/2.
    pub fn euler_rate_matrix(&self) -> Matrix3<f64> {
        let AttitudeTrig { sf, cf, st, ct, .. } = *self;
        let tt = st / ct;
        Matrix3::new(1.0, sf * tt, cf * tt, 0.0, cf, -sf, 0.0, sf / ct, cf / ct)
    }
}

impl AttitudeTrig {
    /// R_r^-1 in closed form: Omega = R_r^-1 A' (the body rates of given Euler-angle rates).
    pub fn euler_rate_matrix_inverse(&self) -> Matrix3<f64> {
        let AttitudeTrig { sf, cf, st, ct, .. } = *self;
        Matrix3::new(1.0, 0.0, -st, 0.0, cf, sf * ct, 0.0, -sf, cf * ct)
    }
}

/// Third column of R_t (the thrust direction R_t e_3), without building the whole matrix.
pub fn thrust_axis(a: &Vector3<f64>) -> Vector3<f64> {
    AttitudeTrig::of(a).thrust_axis()
}

/// R_r of eq. (2): body rates to Euler-angle rates, A' = R_r Omega. Singular at theta = +-pi/2.
pub fn euler_rate_matrix(a: &Vector3<f64>) -> Matrix3<f64> {
    AttitudeTrig::of(a).euler_rate_matrix()
}

/// S(Omega): the skew matrix with S(a) b = a x b.
pub fn skew(w: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -w[2], w[1], w[2], 0.0, -w[0], -w[1], w[0], 0.0)
}

/// F_iA = -J^-1 S(Omega) J Omega - J^-1 K_D Omega of eq. (2) for the inertia diagonal `j` and the
/// damping diagonal `drag` (also the controller's nominal model).
pub fn rotational_drift(j: &Vector3<f64>, drag: &Vector3<f64>, w: &Vector3<f64>) -> Vector3<f64> {
    let jw = w.component_mul(j);
    -(w.cross(&jw) + drag.component_mul(w)).component_div(j)
}
