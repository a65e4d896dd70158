//! Scalar building blocks with their first and second time derivatives.

/// A scalar signal with its first and second time derivatives.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Jet {
    /// Value.
    pub v: f64,
    /// First time derivative.
    pub d: f64,
    /// Second time derivative.
    pub dd: f64,
}

impl Jet {
    /// A constant.
    pub fn constant(v: f64) -> Jet {
        Jet { v, d: 0.0, dd: 0.0 }
    }

    /// Product rule (a plain method: the jets are built in `const`-like chains, not operators).
    #[allow(clippy::should_implement_trait)]
    pub fn mul(self, o: Jet) -> Jet {
        Jet {
            v: self.v * o.v,
            d: self.d * o.v + self.v * o.d,
            dd: self.dd * o.v + 2.0 * self.d * o.d + self.v * o.dd,
        }
    }

    /// Sum.
    #[allow(clippy::should_implement_trait)]
    pub fn add(self, o: Jet) -> Jet {
        Jet {
            v: self.v + o.v,
            d: self.d + o.d,
            dd: self.dd + o.dd,
        }
    }

    /// Scaling by a constant.
    pub fn scale(self, k: f64) -> Jet {
        Jet {
            v: self.v * k,
            d: self.d * k,
            dd: self.dd * k,
        }
    }

    /// sin and cos of the signal, each with derivatives.
    pub fn sin_cos(self) -> (Jet, Jet) {
        let (s, c) = self.v.sin_cos();
        let sin = Jet {
            v: s,
            d: c * self.d,
            dd: -s * self.d * self.d + c * self.dd,
        };
        let cos = Jet {
            v: c,
            d: -s * self.d,
            dd: -c * self.d * self.d - s * self.dd,
        };
        (sin, cos)
    }
}

/// 1 - e^{-r t}: rises from 0 to 1 at rate r.
pub fn rise(r: f64, t: f64) -> Jet {
    let e = (-r * t).exp();
    Jet {
        v: 1.0 - e,
        d: r * e,
        dd: -r * r * e,
    }
}

/// atan(k (t - t0)) / pi + 1/2: a smooth step from 0 to 1 around t0 with sharpness k.
pub fn smooth_step(k: f64, t0: f64, t: f64) -> Jet {
    let u = k * (t - t0);
    let q = 1.0 + u * u;
    Jet {
        v: u.atan() / std::f64::consts::PI + 0.5,
        d: k / (std::f64::consts::PI * q),
        dd: -2.0 * k * k * u / (std::f64::consts::PI * q * q),
    }
}

/// The time itself.
pub fn time(t: f64) -> Jet {
    Jet {
        v: t,
        d: 1.0,
        dd: 0.0,
    }
}
