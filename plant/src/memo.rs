//! The transcendental functions of the time profiles (faults (63)-(64), disturbance (62), model
//! perturbation D9), evaluated directly or through a memo shared by the quadrotors of a plant.
//!
//! The profiles of different quadrotors often evaluate the same function at the same argument in a
//! step (the same rates and phases, a rate of 0): e^{-t} of every fault profile, sin(w t + p) of a
//! phase two quadrotors share, e^{-0 t}. A memo keyed by the argument's bits returns the value the
//! function gave for those bits, so a profile computed through it is bit for bit the one computed
//! directly, and each distinct argument of a step costs one evaluation.

/// exp, sin and cos as the profiles call them.
pub trait Math {
    /// e^x.
    fn exp(&mut self, x: f64) -> f64;
    /// sin x.
    fn sin(&mut self, x: f64) -> f64;
    /// cos x.
    fn cos(&mut self, x: f64) -> f64;
}

/// Every call evaluated (the profiles of one quadrotor alone, tests, checks).
#[derive(Debug, Clone, Copy, Default)]
pub struct Direct;

impl Math for Direct {
    fn exp(&mut self, x: f64) -> f64 {
        x.exp()
    }
    fn sin(&mut self, x: f64) -> f64 {
        x.sin()
    }
    fn cos(&mut self, x: f64) -> f64 {
        x.cos()
    }
}

/// log2 of the slots of each function's table: 128 slots, room for the distinct arguments of a
/// step of a few dozen quadrotors with few collisions (a collision costs an evaluation, never a
/// wrong value).
const SLOT_BITS: u32 = 7;

/// A direct-mapped table of one function's values by argument bits.
#[derive(Debug, Clone)]
struct Table {
    keys: [u64; 1 << SLOT_BITS],
    values: [f64; 1 << SLOT_BITS],
}

impl Table {
    /// Every slot holds f(+0.0): a valid entry from the start.
    fn new(f: fn(f64) -> f64) -> Table {
        Table {
            keys: [0.0f64.to_bits(); 1 << SLOT_BITS],
            values: [f(0.0); 1 << SLOT_BITS],
        }
    }

    #[inline]
    fn get(&mut self, x: f64, f: fn(f64) -> f64) -> f64 {
        let bits = x.to_bits();
        // Fibonacci hashing: the top bits of the product mix every bit of the argument.
        let slot = (bits.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - SLOT_BITS)) as usize;
        if self.keys[slot] == bits {
            return self.values[slot];
        }
        let v = f(x);
        self.keys[slot] = bits;
        self.values[slot] = v;
        v
    }
}

/// The memo of a plant: one table per function.
#[derive(Debug, Clone)]
pub struct Memo {
    exp: Table,
    sin: Table,
    cos: Table,
}

impl Default for Memo {
    fn default() -> Memo {
        Memo {
            exp: Table::new(f64::exp),
            sin: Table::new(f64::sin),
            cos: Table::new(f64::cos),
        }
    }
}

impl Math for Memo {
    fn exp(&mut self, x: f64) -> f64 {
        self.exp.get(x, f64::exp)
    }
    fn sin(&mut self, x: f64) -> f64 {
        self.sin.get(x, f64::sin)
    }
    fn cos(&mut self, x: f64) -> f64 {
        self.cos.get(x, f64::cos)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_memo_returns_the_bits_of_the_direct_evaluation_for_every_argument() {
        let mut m = Memo::default();
        let mut d = Direct;
        let mut args = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        // Many arguments, repeated, so that slots are hit, missed and overwritten.
        for k in 0..2000 {
            args.push(k as f64 * 0.37 - 300.0);
            args.push(-(k as f64) * 1e-3);
        }
        for round in 0..3 {
            for &x in &args {
                for (got, want) in [
                    (m.exp(x), d.exp(x)),
                    (m.sin(x), d.sin(x)),
                    (m.cos(x), d.cos(x)),
                ] {
                    assert!(
                        got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                        "round {round}, x = {x}: {got} vs {want}"
                    );
                }
            }
        }
    }
}
