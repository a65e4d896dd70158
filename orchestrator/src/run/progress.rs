//! The progress line on stderr (updated in place on a terminal).

use std::io::{IsTerminal, Write};
use std::time::Instant;

/// Steps/s and simulated time of a running run.
pub struct Progress {
    start: Instant,
    last: Instant,
    steps: u64,
    dt: f64,
    tty: bool,
}

impl Progress {
    /// A progress display for a run of `steps` steps of `dt` seconds.
    pub fn new(steps: u64, dt: f64) -> Progress {
        let now = Instant::now();
        Progress {
            start: now,
            last: now,
            steps,
            dt,
            tty: std::io::stderr().is_terminal(),
        }
    }

    fn line(&self, done: u64) -> String {
        let wall = self.start.elapsed().as_secs_f64().max(1e-9);
        let sim = done as f64 * self.dt;
        format!(
            "lockstep: step {done}/{}  t = {sim:.2} s  {:.0} steps/s  {:.1}x real time",
            self.steps,
            done as f64 / wall,
            sim / wall
        )
    }

    /// Redraws the line at most every 200 ms (terminal only).
    pub fn show(&mut self, done: u64) {
        if self.tty && self.last.elapsed().as_millis() >= 200 {
            self.last = Instant::now();
            let mut e = std::io::stderr();
            let _ = write!(e, "\r{}\x1b[K", self.line(done));
            let _ = e.flush();
        }
    }

    /// Prints the final line.
    pub fn finish(&self, done: u64) {
        let mut e = std::io::stderr();
        let lead = if self.tty { "\r" } else { "" };
        let tail = if self.tty { "\x1b[K" } else { "" };
        let _ = writeln!(e, "{lead}{}{tail}", self.line(done));
    }
}
