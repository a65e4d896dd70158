//! The tan-type barrier Lyapunov function of eq. (31) and (40) and the terms it contributes to the
//! control laws (34) and (45), written so that every term is finite at z = 0.
//!
//! With s = pi ||z||² / (2 C²):
//! * V_B = (C² / pi) tan(s)                                        (31), (40)
//! * nu  = z / cos²(s)                                             (definition after Remark 4)
//! * the term z / (zᵀz) (C²/pi) sin(s) cos(s) of (34), (45) equals (z / 2) sin(2s) / (2s), which
//!   tends to z / 2 as z -> 0 (so it is evaluated in that form).
//!
//! A barrier that is reached or crossed (s >= pi/2) has no finite value; [`Barrier::at`] clamps s just
//! below pi/2 so that the control stays finite and the crossing is reported by the `crossed` flag.

use nalgebra::Vector3;

/// Fraction of pi/2 at which s is clamped when the barrier is reached.
pub const BARRIER_CLAMP: f64 = 0.995;

/// BLF quantities at one error z for a barrier width C.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Barrier {
    /// nu = z / cos²(s).
    pub nu: Vector3<f64>,
    /// z / (zᵀz) (C²/pi) sin(s) cos(s) = (z/2) sinc(2s).
    pub sincos_term: Vector3<f64>,
    /// cos²(s).
    pub cos_sq: f64,
    /// V_B = (C²/pi) tan(s).
    pub value: f64,
    /// True when ||z|| >= C (the constraint is reached or violated).
    pub crossed: bool,
}

impl Barrier {
    /// Evaluates the barrier at `z` with width `c` (> 0). With `c = inf` it returns the quadratic limit of
    /// Remark 4 (nu = z, term = z/2, V = zᵀz/2).
    pub fn at(z: &Vector3<f64>, c: f64) -> Barrier {
        let zz = z.norm_squared();
        if !c.is_finite() {
            return Barrier {
                nu: *z,
                sincos_term: z * 0.5,
                cos_sq: 1.0,
                value: 0.5 * zz,
                crossed: false,
            };
        }
        let c2 = c * c;
        let s_raw = std::f64::consts::PI * zz / (2.0 * c2);
        let crossed = s_raw >= std::f64::consts::FRAC_PI_2;
        let s = s_raw.min(BARRIER_CLAMP * std::f64::consts::FRAC_PI_2);
        let cos = s.cos();
        let cos_sq = cos * cos;
        let two_s = 2.0 * s;
        let sinc = if two_s < 1e-8 {
            1.0 - two_s * two_s / 6.0
        } else {
            two_s.sin() / two_s
        };
        Barrier {
            nu: z / cos_sq,
            sincos_term: z * (0.5 * sinc),
            cos_sq,
            value: c2 / std::f64::consts::PI * s.tan(),
            crossed,
        }
    }
}
