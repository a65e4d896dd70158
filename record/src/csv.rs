//! `trajectory.csv` (columns documented in docs/formats.md). Floats are written in their shortest
//! round-trip form, so equal trajectories give byte-equal files.

use super::metrics::Metrics;
use super::sink::{Sink, StepRows};
use formation_config::protocol::wire::{ControlCommand, PlantTruth, ReferenceFrame};
use formation_config::Scenario;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::sync::mpsc::RecvTimeoutError;
use std::time::{Duration, Instant};

/// Longest time written rows stay in the writer's buffer.
pub const FLUSH_EVERY: Duration = Duration::from_secs(1);

/// Output steps handed to the writer thread in one message. Every message wakes the sleeping
/// writer thread: a futex wake-up on the simulation thread, 6 % of `formation sim`'s samples when
/// each step was a message of its own (`perf record`, paper scenario, 2-vCPU VM, 2026-12-03).
pub const STEPS_PER_BATCH: usize = 64;

/// Longest time an output step waits in a batch before the batch is handed over anyway, so a
/// run on the wall clock (100 output steps a second at the paper's decimation) still reaches its
/// file within `BATCH_LATENCY + FLUSH_EVERY`.
pub const BATCH_LATENCY: Duration = Duration::from_millis(100);

/// The columns of `trajectory.csv`, in file order (meanings and units: docs/formats.md). The
/// writer's header and every reader take their names from here.
macro_rules! columns {
    ($($variant:ident = $name:literal,)*) => {
        /// One column of `trajectory.csv`; its position in the file is its index in [`Column::ALL`].
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum Column {
            $(
                #[doc = concat!("`", $name, "` (docs/formats.md)")]
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
        }

        /// Column names, in file order (the header line).
        pub const COLUMNS: &[&str] = &[$($name,)*];
    };
}

columns! {
    Step = "step",
    T = "t",
    Agent = "agent",
    Px = "px",
    Py = "py",
    Pz = "pz",
    Vx = "vx",
    Vy = "vy",
    Vz = "vz",
    Phi = "phi",
    Theta = "theta",
    Psi = "psi",
    P = "p",
    Q = "q",
    R = "r",
    Pdx = "pdx",
    Pdy = "pdy",
    Pdz = "pdz",
    Ex = "ex",
    Ey = "ey",
    Ez = "ez",
    ENorm = "e_norm",
    Tx = "tx",
    Ty = "ty",
    Upx = "upx",
    Upy = "upy",
    Upz = "upz",
    Thrust = "thrust",
    PhiC = "phi_c",
    ThetaC = "theta_c",
    PsiC = "psi_c",
    PhiCRaw = "phi_c_raw",
    ThetaCRaw = "theta_c_raw",
    AlphaX = "alpha_x",
    AlphaY = "alpha_y",
    AlphaZ = "alpha_z",
    AttNorm = "att_norm",
    AttCmdNorm = "att_cmd_norm",
    C1Bar = "c1_bar",
    RateNorm = "rate_norm",
    AlphaNorm = "alpha_norm",
    C2Bar = "c2_bar",
    Blf1 = "blf1",
    Blf2 = "blf2",
    UAcX = "u_ac_x",
    UAcY = "u_ac_y",
    UAcZ = "u_ac_z",
    UAX = "u_a_x",
    UAY = "u_a_y",
    UAZ = "u_a_z",
    GammaX = "gamma_x",
    GammaY = "gamma_y",
    GammaZ = "gamma_z",
    GammaHatX = "gamma_hat_x",
    GammaHatY = "gamma_hat_y",
    GammaHatZ = "gamma_hat_z",
    DeltaX = "delta_x",
    DeltaY = "delta_y",
    DeltaZ = "delta_z",
    DeltaHatX = "delta_hat_x",
    DeltaHatY = "delta_hat_y",
    DeltaHatZ = "delta_hat_z",
    DNorm = "d_norm",
    DHat = "d_hat",
    FX = "f_x",
    FY = "f_y",
    FZ = "f_z",
    FHatX = "f_hat_x",
    FHatY = "f_hat_y",
    FHatZ = "f_hat_z",
    NnNorm = "nn_norm",
    Tau = "tau",
}

enum Msg {
    /// Consecutive output steps, in order.
    Steps(Vec<StepRows>),
    /// An injection (a line of `events.jsonl`) for `run.mcap`.
    Event(serde_json::Value),
    Flush(std::sync::mpsc::SyncSender<std::io::Result<()>>),
}

/// The sinks the writer thread owns, in the order they are written.
struct Sinks(Vec<Box<dyn Sink>>);

impl Sinks {
    fn step(&mut self, r: &StepRows) -> std::io::Result<()> {
        self.0.iter_mut().try_for_each(|s| s.step(r))
    }

    fn event(&mut self, line: &serde_json::Value) -> std::io::Result<()> {
        self.0.iter_mut().try_for_each(|s| s.event(line))
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.0.iter_mut().try_for_each(|s| s.flush())
    }

    /// Flushes and completes every sink; the first failure is returned, the others still close.
    fn close(mut self) -> std::io::Result<()> {
        let flushed = self.flush();
        // Every sink is finished before the first failure is picked.
        let finished: Vec<std::io::Result<()>> = self.0.into_iter().map(|s| s.finish()).collect();
        flushed.and(finished.into_iter().collect())
    }
}

/// The recorder's writer of its file outputs (`trajectory.csv`, `run.mcap`, the rosbag2: the
/// [`Sink`]s of the run): formatting and writing run on a thread of their own, off the simulation
/// loop (the formatting code is the same, so the bytes are too).
pub struct TrajectoryWriter {
    tx: Option<std::sync::mpsc::SyncSender<Msg>>,
    handle: Option<std::thread::JoinHandle<std::io::Result<()>>>,
    /// Output steps not handed over yet (at most `STEPS_PER_BATCH`).
    batch: Vec<StepRows>,
    /// When the oldest step of `batch` was queued.
    batch_since: Instant,
}

impl TrajectoryWriter {
    /// Starts the writer thread over `sinks` (their files created).
    pub(crate) fn create(sinks: Vec<Box<dyn Sink>>) -> std::io::Result<TrajectoryWriter> {
        let mut rows = Sinks(sinks);
        let (tx, rx) = std::sync::mpsc::sync_channel::<Msg>(1024);
        let handle = std::thread::Builder::new()
            .name("csv-writer".into())
            .spawn(move || -> std::io::Result<()> {
                formation_config::node::sched::background_thread();
                // Rows reach the file at least every FLUSH_EVERY, so a killed run leaves a
                // readable prefix (whole lines: the buffer is written out between rows).
                let mut flushed = Instant::now();
                let mut pending = false;
                loop {
                    let wait = if pending {
                        FLUSH_EVERY.saturating_sub(flushed.elapsed())
                    } else {
                        Duration::from_secs(3600)
                    };
                    match rx.recv_timeout(wait) {
                        Ok(Msg::Steps(batch)) => {
                            for r in &batch {
                                rows.step(r)?;
                            }
                            pending = true;
                        }
                        Ok(Msg::Event(line)) => rows.event(&line)?,
                        Ok(Msg::Flush(reply)) => {
                            let _ = reply.send(rows.flush());
                            (flushed, pending) = (Instant::now(), false);
                        }
                        Err(RecvTimeoutError::Timeout) => {}
                        Err(RecvTimeoutError::Disconnected) => break,
                    }
                    if pending && flushed.elapsed() >= FLUSH_EVERY {
                        rows.flush()?;
                        (flushed, pending) = (Instant::now(), false);
                    }
                }
                rows.close()
            })?;
        Ok(TrajectoryWriter {
            tx: Some(tx),
            handle: Some(handle),
            batch: Vec::with_capacity(STEPS_PER_BATCH),
            batch_since: Instant::now(),
        })
    }

    /// Queues one row per agent for this step.
    pub fn write_step(
        &mut self,
        r: &ReferenceFrame,
        truths: &[PlantTruth],
        commands: &[ControlCommand],
        metrics: &Metrics,
    ) -> std::io::Result<()> {
        let n = truths.len();
        let rows = StepRows {
            p_d: r.p_d,
            target: r.target,
            offsets: r.offset[..n].to_vec(),
            truths: truths.to_vec(),
            commands: commands.to_vec(),
            errors: metrics.agents.iter().map(|a| a.last_error).collect(),
        };
        if self.batch.is_empty() {
            self.batch_since = Instant::now();
        }
        self.batch.push(rows);
        if self.batch.len() >= STEPS_PER_BATCH || self.batch_since.elapsed() >= BATCH_LATENCY {
            self.hand_over()?;
        }
        Ok(())
    }

    /// Sends the batch of output steps to the writer thread.
    fn hand_over(&mut self) -> std::io::Result<()> {
        if self.batch.is_empty() {
            return Ok(());
        }
        let batch = std::mem::replace(&mut self.batch, Vec::with_capacity(STEPS_PER_BATCH));
        self.send(Msg::Steps(batch))
    }

    /// Queues an injection (a line of `events.jsonl`) for `run.mcap` (ignored without it), after
    /// the steps queued before it.
    pub fn write_event(&mut self, line: serde_json::Value) -> std::io::Result<()> {
        self.hand_over()?;
        self.send(Msg::Event(line))
    }

    /// Waits until everything queued so far is written and flushed to the file.
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.hand_over()?;
        let (reply_tx, reply_rx) = std::sync::mpsc::sync_channel(1);
        self.send(Msg::Flush(reply_tx))?;
        reply_rx.recv().map_err(|_| self.stopped())?
    }

    /// Writes everything queued and stops the thread.
    pub fn close(mut self) -> std::io::Result<()> {
        self.hand_over()?;
        self.tx.take();
        match self.handle.take().map(|h| h.join()) {
            Some(Ok(result)) => result,
            Some(Err(_)) => Err(std::io::Error::other(
                "the trajectory writer thread panicked",
            )),
            None => Ok(()),
        }
    }

    fn send(&mut self, msg: Msg) -> std::io::Result<()> {
        let sent = self
            .tx
            .as_ref()
            .map(|tx| tx.send(msg).is_ok())
            .unwrap_or(false);
        if sent {
            Ok(())
        } else {
            Err(self.stopped())
        }
    }

    /// The error of a writer thread that stopped (it failed to write).
    fn stopped(&mut self) -> std::io::Error {
        self.tx.take();
        match self.handle.take().map(|h| h.join()) {
            Some(Ok(Err(e))) => e,
            _ => std::io::Error::other("the trajectory writer stopped"),
        }
    }
}

impl Drop for TrajectoryWriter {
    fn drop(&mut self) {
        let _ = self.hand_over();
        self.tx.take();
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
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
    fn write_rows(&mut self, rows: &StepRows) -> std::io::Result<()> {
        let mut fmt = ryu::Buffer::new();
        let r = rows;
        for (i, (tr, cmd)) in rows.truths.iter().zip(&rows.commands).enumerate() {
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
                r.p_d[0] + r.offsets[i][0],
                r.p_d[1] + r.offsets[i][1],
                r.p_d[2] + r.offsets[i][2],
            ];
            let e = [
                st.position[0] - pd[0],
                st.position[1] - pd[1],
                st.position[2] - pd[2],
            ];
            let att_cmd_norm = norm(tm.attitude_cmd);
            let d_norm = norm(tr.disturbance);
            let values: [&[f64]; 26] = [
                &st.position,
                &st.velocity,
                &st.attitude,
                &st.rate,
                &pd,
                &e,
                &[rows.errors[i]],
                &r.target[..2],
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
    fn step(&mut self, rows: &StepRows) -> std::io::Result<()> {
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

    /// Writes `steps` output steps of the paper's five agents, stamped 0, 1, ..., and returns the
    /// step column of the file after a flush.
    fn steps_in_file(w: &mut TrajectoryWriter, path: &Path, from: u64, to: u64) -> Vec<u64> {
        let s = Scenario::paper();
        let metrics = Metrics::new(&s);
        let n = s.n_agents();
        for k in from..to {
            let mut truths = vec![PlantTruth::default(); n];
            for t in &mut truths {
                t.state.step = k;
            }
            let commands = vec![ControlCommand::default(); n];
            w.write_step(&ReferenceFrame::default(), &truths, &commands, &metrics)
                .unwrap();
        }
        w.flush().unwrap();
        std::fs::read_to_string(path)
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').next().unwrap().parse().unwrap())
            .collect()
    }

    #[test]
    fn batched_steps_reach_the_file_in_order_and_whole_at_every_flush() {
        let dir = std::env::temp_dir().join(format!("formation-csv-batch-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("trajectory.csv");
        let s = Scenario::paper();
        let mut w = TrajectoryWriter::create(vec![Box::new(RowWriter::create(&path, &s).unwrap())])
            .unwrap();
        // Two and a half batches, then a few steps fewer than a batch: a flush hands over the
        // partial batch, so the file holds every step queued, five rows each, in order.
        let total = (5 * STEPS_PER_BATCH / 2) as u64;
        let first = steps_in_file(&mut w, &path, 0, total);
        let expected: Vec<u64> = (0..total).flat_map(|k| [k; 5]).collect();
        assert_eq!(first, expected);
        let second = steps_in_file(&mut w, &path, total, total + 3);
        let expected: Vec<u64> = (0..total + 3).flat_map(|k| [k; 5]).collect();
        assert_eq!(second, expected);
        w.close().unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
