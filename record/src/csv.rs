//! `trajectory.csv` (columns documented in docs/formats.md). Floats are written in their shortest
//! round-trip form, so equal trajectories give byte-equal files.

use super::sink::{Cadence, Sink, Step};
use formation_config::Scenario;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

/// The columns of `trajectory.csv`, in file order, each with its unit and meaning: the one list the
/// writer's header, docs/formats.md (checked by a test) and every reader take their names from.
macro_rules! columns {
    ($($variant:ident = $name:literal, $unit:literal, $meaning:literal;)*) => {
        /// One column of `trajectory.csv`; its position in the file is its index in [`Column::ALL`].
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum Column {
            $(
                #[doc = concat!("`", $name, "`: ", $meaning, " (", $unit, ")")]
                $variant,
            )*
        }

        impl Column {
            /// Every column, in file order.
            pub const ALL: &'static [Column] = &[$(Column::$variant,)*];

            /// The column's name in the header.
            pub const fn name(self) -> &'static str {
                match self {
                    $(Column::$variant => $name,)*
                }
            }

            /// Its unit (SI; `-` for a count or a number without unit).
            pub const fn unit(self) -> &'static str {
                match self {
                    $(Column::$variant => $unit,)*
                }
            }

            /// What it holds ("true": from the plant; a command or estimate: from the controller).
            pub const fn meaning(self) -> &'static str {
                match self {
                    $(Column::$variant => $meaning,)*
                }
            }

            /// The column named `name` in a header.
            pub fn named(name: &str) -> Option<Column> {
                Column::ALL.iter().copied().find(|c| c.name() == name)
            }
        }

        /// Column names, in file order (the header line).
        pub const COLUMNS: &[&str] = &[$($name,)*];
    };
}

columns! {
    Step = "step", "-", "simulation step k";
    T = "t", "s", "simulation time t_k = k dt";
    Agent = "agent", "-", "agent index i, 1-based";
    Px = "px", "m", "true position P_i, x";
    Py = "py", "m", "true position P_i, y";
    Pz = "pz", "m", "true position P_i, z";
    Vx = "vx", "m/s", "true velocity V_i, x";
    Vy = "vy", "m/s", "true velocity V_i, y";
    Vz = "vz", "m/s", "true velocity V_i, z";
    Phi = "phi", "rad", "true roll phi (attitude A_i)";
    Theta = "theta", "rad", "true pitch theta (attitude A_i)";
    Psi = "psi", "rad", "true yaw psi (attitude A_i)";
    P = "p", "rad/s", "true body rate Omega_i, p";
    Q = "q", "rad/s", "true body rate Omega_i, q";
    R = "r", "rad/s", "true body rate Omega_i, r";
    Pdx = "pdx", "m", "desired position P_d + Delta_i0 (undelayed), x";
    Pdy = "pdy", "m", "desired position P_d + Delta_i0 (undelayed), y";
    Pdz = "pdz", "m", "desired position P_d + Delta_i0 (undelayed), z";
    Ex = "ex", "m", "formation error P_i - P_d - Delta_i0, x";
    Ey = "ey", "m", "formation error P_i - P_d - Delta_i0, y";
    Ez = "ez", "m", "formation error P_i - P_d - Delta_i0, z";
    ENorm = "e_norm", "m", "norm of the formation error";
    Tx = "tx", "m", "ground target T_g, x";
    Ty = "ty", "m", "ground target T_g, y";
    Upx = "upx", "m/s^2", "position control U_iP after the limits, eq. (14), x";
    Upy = "upy", "m/s^2", "position control U_iP after the limits, eq. (14), y";
    Upz = "upz", "m/s^2", "position control U_iP after the limits, eq. (14), z";
    Thrust = "thrust", "N", "total thrust applied";
    PhiC = "phi_c", "rad", "filtered attitude command A_iC (command filter 1), roll";
    ThetaC = "theta_c", "rad", "filtered attitude command A_iC, pitch";
    PsiC = "psi_c", "rad", "filtered attitude command A_iC, yaw";
    PhiCRaw = "phi_c_raw", "rad", "raw attitude command of eq. (28), roll";
    ThetaCRaw = "theta_c_raw", "rad", "raw attitude command of eq. (28), pitch";
    AlphaX = "alpha_x", "rad/s", "filtered virtual control alpha_i, x";
    AlphaY = "alpha_y", "rad/s", "filtered virtual control alpha_i, y";
    AlphaZ = "alpha_z", "rad/s", "filtered virtual control alpha_i, z";
    AttNorm = "att_norm", "rad", "norm of the attitude A_i";
    AttCmdNorm = "att_cmd_norm", "rad", "norm of the attitude command A_iC";
    C1Bar = "c1_bar", "rad", "attitude constraint C1-bar_i = |A_iC| + margin";
    RateNorm = "rate_norm", "rad/s", "norm of the body rate Omega_i";
    AlphaNorm = "alpha_norm", "rad/s", "norm of the virtual control alpha_i";
    C2Bar = "c2_bar", "rad/s", "rate constraint C2-bar_i";
    Blf1 = "blf1", "-", "barrier value V_i1B, eq. (31)";
    Blf2 = "blf2", "-", "barrier value V_i2B, eq. (40)";
    UAcX = "u_ac_x", "N m", "torque command U_iAC, x";
    UAcY = "u_ac_y", "N m", "torque command U_iAC, y";
    UAcZ = "u_ac_z", "N m", "torque command U_iAC, z";
    UAX = "u_a_x", "N m", "torque applied U_iA after faults (4) and saturation (3), x";
    UAY = "u_a_y", "N m", "torque applied U_iA, y";
    UAZ = "u_a_z", "N m", "torque applied U_iA, z";
    GammaX = "gamma_x", "-", "true actuator effectiveness Gamma_i, x";
    GammaY = "gamma_y", "-", "true actuator effectiveness Gamma_i, y";
    GammaZ = "gamma_z", "-", "true actuator effectiveness Gamma_i, z";
    GammaHatX = "gamma_hat_x", "-", "estimate Gamma-hat_i, x";
    GammaHatY = "gamma_hat_y", "-", "estimate Gamma-hat_i, y";
    GammaHatZ = "gamma_hat_z", "-", "estimate Gamma-hat_i, z";
    DeltaX = "delta_x", "N m", "true actuator bias delta_i, x";
    DeltaY = "delta_y", "N m", "true actuator bias delta_i, y";
    DeltaZ = "delta_z", "N m", "true actuator bias delta_i, z";
    DeltaHatX = "delta_hat_x", "N m", "estimate delta-hat_i, x";
    DeltaHatY = "delta_hat_y", "N m", "estimate delta-hat_i, y";
    DeltaHatZ = "delta_hat_z", "N m", "estimate delta-hat_i, z";
    DNorm = "d_norm", "rad/s^2", "norm of the true attitude disturbance D_iA";
    DHat = "d_hat", "rad/s^2", "estimate D-hat_iA, eq. (49)";
    FX = "f_x", "m/s^2", "true lumped uncertainty F_iP, x";
    FY = "f_y", "m/s^2", "true lumped uncertainty F_iP, y";
    FZ = "f_z", "m/s^2", "true lumped uncertainty F_iP, z";
    FHatX = "f_hat_x", "m/s^2", "RBFNN output F-hat_iP, x";
    FHatY = "f_hat_y", "m/s^2", "RBFNN output F-hat_iP, y";
    FHatZ = "f_hat_z", "m/s^2", "RBFNN output F-hat_iP, z";
    NnNorm = "nn_norm", "-", "Frobenius norm of the RBFNN weights W-hat_i";
    Tau = "tau", "s", "delay tau_i(t) the agent applied";
    SepUx = "sep_ux", "m/s^2", "separation layer's correction U_iS - U_iP (D25), x; 0 while it does not act";
    SepUy = "sep_uy", "m/s^2", "separation layer's correction U_iS - U_iP, y";
    SepUz = "sep_uz", "m/s^2", "separation layer's correction U_iS - U_iP, z";
    SepPred = "sep_pred", "m", "smallest predicted separation to another quadrotor from the delayed broadcast (D25); inf with none in range";
}

/// Buffered, synchronous writer of `trajectory.csv` rows (runs on the writer thread).
pub(crate) struct RowWriter {
    out: BufWriter<File>,
    margin: f64,
    rate_limit: f64,
    line: String,
}

impl RowWriter {
    /// Creates the file and writes the header.
    pub(crate) fn create(path: &Path, s: &Scenario) -> std::io::Result<RowWriter> {
        let mut out = BufWriter::with_capacity(
            1 << 20,
            formation_config::node::files::create_replacing(path)?,
        );
        writeln!(out, "{}", COLUMNS.join(","))?;
        Ok(RowWriter {
            out,
            margin: s.controller.attitude.attitude_margin_rad,
            rate_limit: s.controller.attitude.rate_limit_rad_s,
            line: String::with_capacity(2048),
        })
    }

    /// Writes one row per agent for this step.
    fn write_rows(&mut self, rows: &Step<'_>) -> std::io::Result<()> {
        let mut fmt = ryu::Buffer::new();
        let (p_d, offsets, target) = (rows.p_d(), rows.offsets(), rows.target());
        for (i, (tr, cmd)) in rows.truths.iter().zip(rows.commands).enumerate() {
            let st = &tr.state;
            let tm = &cmd.telemetry;
            let line = &mut self.line;
            line.clear();
            line.push_str(itoa::Buffer::new().format(st.step));
            line.push(',');
            push(line, &mut fmt, st.t);
            line.push(',');
            line.push_str(itoa::Buffer::new().format(i + 1));
            let pd = [
                p_d[0] + offsets[i][0],
                p_d[1] + offsets[i][1],
                p_d[2] + offsets[i][2],
            ];
            let e = [
                st.position[0] - pd[0],
                st.position[1] - pd[1],
                st.position[2] - pd[2],
            ];
            let att_cmd_norm = norm(tm.attitude_cmd);
            let d_norm = norm(tr.disturbance);
            let values: [&[f64]; 28] = [
                &st.position,
                &st.velocity,
                &st.attitude,
                &st.rate,
                &pd,
                &e,
                &[rows.errors[i]],
                &target[..2],
                &tm.u_p,
                &[tr.thrust_n],
                &tm.attitude_cmd,
                &tm.attitude_cmd_raw[..2],
                &tm.alpha,
                &[norm(st.attitude), att_cmd_norm, att_cmd_norm + self.margin],
                &[norm(st.rate), norm(tm.alpha), self.rate_limit],
                &[tm.blf1, tm.blf2],
                &cmd.torque_nm,
                &tr.torque_applied_nm,
                &tr.gamma,
                &tm.gamma_hat,
                &tr.delta,
                &tm.delta_hat,
                &[d_norm, tm.d_hat],
                &tr.uncertainty,
                &tm.f_hat,
                &[tm.nn_weight_norm, tm.tau_s],
                &tm.sep_correction,
                &[tm.sep_predicted_m],
            ];
            for group in values {
                for v in group {
                    line.push(',');
                    push(line, &mut fmt, *v);
                }
            }
            line.push('\n');
            self.out.write_all(line.as_bytes())?;
        }
        Ok(())
    }
}

impl Sink for RowWriter {
    fn cadence(&self) -> Cadence {
        Cadence::Output
    }

    fn step(&mut self, rows: &Step<'_>) -> std::io::Result<()> {
        self.write_rows(rows)
    }

    /// Flushes the buffer to the file.
    fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }

    fn finish(mut self: Box<Self>) -> std::io::Result<()> {
        self.out.flush()
    }
}

fn push(line: &mut String, fmt: &mut ryu::Buffer, v: f64) {
    if v.is_finite() {
        line.push_str(fmt.format_finite(v));
    } else if v.is_nan() {
        line.push_str("NaN");
    } else if v > 0.0 {
        line.push_str("inf");
    } else {
        line.push_str("-inf");
    }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_has_every_documented_column_once() {
        let mut seen = std::collections::HashSet::new();
        for c in COLUMNS {
            assert!(seen.insert(*c), "duplicate column {c}");
        }
        let doc = include_str!("../../docs/formats.md");
        for c in COLUMNS {
            assert!(
                doc.contains(&format!("`{c}"))
                    || doc.contains(&format!(" {c} "))
                    || doc.contains(&format!("{c}`")),
                "column {c} is not documented"
            );
        }
    }
}
