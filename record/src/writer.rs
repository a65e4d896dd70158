//! The recorder's writer thread: the file sinks of a run (`trajectory.csv`, `run.mcap`, the
//! rosbag2; [`Cadence::Output`](super::sink::Cadence)) get the output steps and the injections
//! here, in order, off the simulation loop (the formatting code is the same, so the bytes are
//! too).

use super::sink::{Sink, Step};
use formation_config::protocol::wire::{ControlCommand, PlantTruth, ReferenceFrame};
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

/// An output step, copied for the writer thread.
struct StepRows {
    step: u64,
    reference: ReferenceFrame,
    truths: Vec<PlantTruth>,
    commands: Vec<ControlCommand>,
    errors: Vec<f64>,
}

impl StepRows {
    fn of(s: &Step<'_>) -> StepRows {
        StepRows {
            step: s.step,
            reference: *s.reference,
            truths: s.truths.to_vec(),
            commands: s.commands.to_vec(),
            errors: s.errors.to_vec(),
        }
    }

    fn view(&self) -> Step<'_> {
        Step {
            step: self.step,
            reference: &self.reference,
            truths: &self.truths,
            commands: &self.commands,
            errors: &self.errors,
        }
    }
}

enum Msg {
    /// Consecutive output steps, in order.
    Steps(Vec<StepRows>),
    /// An injection (a line of `events.jsonl`).
    Event(serde_json::Value),
    /// A sink that joins from the next step on.
    Add(Box<dyn Sink>),
    Flush(std::sync::mpsc::SyncSender<std::io::Result<()>>),
}

/// The sinks the writer thread owns, in the order they are written.
struct Sinks(Vec<Box<dyn Sink>>);

impl Sinks {
    fn step(&mut self, r: &StepRows) -> std::io::Result<()> {
        let view = r.view();
        self.0.iter_mut().try_for_each(|s| s.step(&view))
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

/// The writer thread of a run's file sinks.
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
                        Ok(Msg::Add(sink)) => rows.0.push(sink),
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

    /// Queues an output step.
    pub(crate) fn write_step(&mut self, step: &Step<'_>) -> std::io::Result<()> {
        if self.batch.is_empty() {
            self.batch_since = Instant::now();
        }
        self.batch.push(StepRows::of(step));
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

    /// Queues an injection (a line of `events.jsonl`), after the steps queued before it.
    pub(crate) fn write_event(&mut self, line: serde_json::Value) -> std::io::Result<()> {
        self.hand_over()?;
        self.send(Msg::Event(line))
    }

    /// Adds a sink: it gets the steps queued from now on.
    pub(crate) fn add(&mut self, sink: Box<dyn Sink>) -> std::io::Result<()> {
        self.hand_over()?;
        self.send(Msg::Add(sink))
    }

    /// Waits until everything queued so far is written and flushed to the file.
    pub(crate) fn flush(&mut self) -> std::io::Result<()> {
        self.hand_over()?;
        let (reply_tx, reply_rx) = std::sync::mpsc::sync_channel(1);
        self.send(Msg::Flush(reply_tx))?;
        reply_rx.recv().map_err(|_| self.stopped())?
    }

    /// Writes everything queued and stops the thread.
    pub(crate) fn close(mut self) -> std::io::Result<()> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::csv::RowWriter;
    use formation_config::Scenario;
    use std::path::Path;

    /// Writes output steps `from..to` of the paper's five agents and returns the step column of
    /// the file after a flush.
    fn steps_in_file(w: &mut TrajectoryWriter, path: &Path, from: u64, to: u64) -> Vec<u64> {
        let n = Scenario::paper().n_agents();
        let reference = ReferenceFrame::default();
        let commands = vec![ControlCommand::default(); n];
        let errors = vec![0.0; n];
        for k in from..to {
            let mut truths = vec![PlantTruth::default(); n];
            for t in &mut truths {
                t.state.step = k;
            }
            let step = Step {
                step: k,
                reference: &reference,
                truths: &truths,
                commands: &commands,
                errors: &errors,
            };
            w.write_step(&step).unwrap();
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
        let dir =
            std::env::temp_dir().join(format!("formation-writer-batch-{}", std::process::id()));
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
