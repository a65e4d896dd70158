//! The recorder's fan-out: every sink of a run gets each step at its [`Cadence`]. The live sinks
//! ([`Cadence::Every`]) are called here, on the run loop's thread, at every step; the file sinks
//! ([`Cadence::Output`]) get the output steps through the writer thread
//! ([`TrajectoryWriter`]). Injections go to every sink, after the steps before them.

use super::sink::{Cadence, Sink, Step};
use super::writer::TrajectoryWriter;

/// The sinks of one run.
pub(crate) struct Fanout {
    /// Live sinks, in the order they were given.
    every: Vec<Box<dyn Sink>>,
    /// The writer thread of the file sinks (none without file sinks).
    writer: Option<TrajectoryWriter>,
}

impl Fanout {
    /// Starts the fan-out over `sinks` (the writer thread if any is a file).
    pub(crate) fn new(sinks: Vec<Box<dyn Sink>>) -> std::io::Result<Fanout> {
        let (files, every): (Vec<_>, Vec<_>) = sinks
            .into_iter()
            .partition(|s| s.cadence() == Cadence::Output);
        let writer = if files.is_empty() {
            None
        } else {
            Some(TrajectoryWriter::create(files)?)
        };
        Ok(Fanout { every, writer })
    }

    /// Adds a sink: it gets the steps from the next one on.
    pub(crate) fn add(&mut self, sink: Box<dyn Sink>) -> std::io::Result<()> {
        match (sink.cadence(), &mut self.writer) {
            (Cadence::Every, _) => self.every.push(sink),
            (Cadence::Output, Some(w)) => w.add(sink)?,
            (Cadence::Output, None) => self.writer = Some(TrajectoryWriter::create(vec![sink])?),
        }
        Ok(())
    }

    /// Whether a sink takes every step (the recorder then builds each step's view).
    pub(crate) fn takes_every_step(&self) -> bool {
        !self.every.is_empty()
    }

    /// Hands step `s` to the live sinks and, if it is an output step, to the file sinks.
    pub(crate) fn step(&mut self, s: &Step<'_>, output: bool) -> std::io::Result<()> {
        for sink in &mut self.every {
            sink.step(s)?;
        }
        match &mut self.writer {
            Some(w) if output => w.write_step(s),
            _ => Ok(()),
        }
    }

    /// Hands an injection (a line of `events.jsonl`) to every sink.
    pub(crate) fn event(&mut self, line: &serde_json::Value) -> std::io::Result<()> {
        for sink in &mut self.every {
            sink.event(line)?;
        }
        match &mut self.writer {
            Some(w) => w.write_event(line.clone()),
            None => Ok(()),
        }
    }

    /// Waits until the file sinks have written and flushed everything queued so far.
    pub(crate) fn flush(&mut self) -> std::io::Result<()> {
        for sink in &mut self.every {
            sink.flush()?;
        }
        match &mut self.writer {
            Some(w) => w.flush(),
            None => Ok(()),
        }
    }

    /// Finishes the live sinks, then writes everything queued and completes the files; the first
    /// failure is returned, every sink still finishes.
    pub(crate) fn finish(self) -> std::io::Result<()> {
        let live: Vec<std::io::Result<()>> = self.every.into_iter().map(|s| s.finish()).collect();
        let files = self.writer.map_or(Ok(()), TrajectoryWriter::close);
        live.into_iter().collect::<std::io::Result<()>>().and(files)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_config::protocol::wire::{ControlCommand, PlantTruth, ReferenceFrame};
    use std::sync::{Arc, Mutex};

    /// What a test sink saw: steps, events, whether it finished.
    #[derive(Default)]
    struct Seen {
        steps: Vec<u64>,
        events: usize,
        finished: bool,
    }

    struct Probe(Cadence, Arc<Mutex<Seen>>);

    impl Sink for Probe {
        fn cadence(&self) -> Cadence {
            self.0
        }
        fn step(&mut self, s: &Step<'_>) -> std::io::Result<()> {
            self.1.lock().unwrap().steps.push(s.step);
            Ok(())
        }
        fn event(&mut self, _: &serde_json::Value) -> std::io::Result<()> {
            self.1.lock().unwrap().events += 1;
            Ok(())
        }
        fn finish(self: Box<Self>) -> std::io::Result<()> {
            self.1.lock().unwrap().finished = true;
            Ok(())
        }
    }

    #[test]
    fn live_sinks_get_every_step_files_the_output_steps_and_both_every_event() {
        let (live, file, late) = (Arc::default(), Arc::default(), Arc::default());
        let mut out = Fanout::new(vec![
            Box::new(Probe(Cadence::Every, Arc::clone(&live))),
            Box::new(Probe(Cadence::Output, Arc::clone(&file))),
        ])
        .unwrap();
        assert!(out.takes_every_step());
        let (reference, truths, commands, errors) = (
            ReferenceFrame::default(),
            [PlantTruth::default()],
            [ControlCommand::default()],
            [0.0],
        );
        for k in 0..25 {
            if k == 12 {
                out.add(Box::new(Probe(Cadence::Every, Arc::clone(&late))))
                    .unwrap();
                out.event(&serde_json::json!({"event": "fault"})).unwrap();
            }
            let s = Step {
                step: k,
                reference: &reference,
                truths: &truths,
                commands: &commands,
                errors: &errors,
            };
            // Output steps: every 10th and a divergence at 23.
            out.step(&s, k % 10 == 0 || k == 23).unwrap();
        }
        out.finish().unwrap();
        let (live, file, late) = (
            live.lock().unwrap(),
            file.lock().unwrap(),
            late.lock().unwrap(),
        );
        assert_eq!(live.steps, (0..25).collect::<Vec<_>>());
        assert_eq!(file.steps, vec![0, 10, 20, 23]);
        assert_eq!(late.steps, (12..25).collect::<Vec<_>>());
        assert_eq!((live.events, file.events, late.events), (1, 1, 1));
        assert!(live.finished && file.finished && late.finished);
    }
}
