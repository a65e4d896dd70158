//! `formation run --zenoh-listen ENDPOINT`: the run's telemetry for readers on other machines over
//! Zenoh (crate `formation-net`, [`formation_net::export`]; docs/multi-host.md, "Outside clients
//! over the network"). Without the `multihost` feature the flag is refused with exit 2.
//!
//! The export is one of the recorder's sinks ([`Running::sink`]): it takes every step the recorder
//! records; the runtime events and the agents' telemetry, which the recorder does not see, its
//! thread reads from the run's services (docs/multi-host.md, "Outside clients over the network").

/// Options of `formation run` for outside readers over the network.
#[derive(clap::Args, Debug, Clone)]
pub struct ExportArgs {
    /// Publish the run's telemetry over Zenoh for readers on other machines (Python
    /// `formation_client.net`, any `eclipse-zenoh` program): listen on this endpoint, e.g.
    /// `tcp/127.0.0.1:7448` (repeatable; default: no export). Beyond loopback only with
    /// `--auth FILE`, whose users are the readers admitted. Keys: docs/multi-host.md.
    #[arg(long, value_name = "ENDPOINT")]
    pub zenoh_listen: Vec<String>,
}

impl ExportArgs {
    /// Whether the run exports anything (it then takes one outside-observer slot).
    pub fn enabled(&self) -> bool {
        !self.zenoh_listen.is_empty()
    }
}

/// What the export tells readers of the run.
#[derive(Debug, Clone)]
pub struct Facts<'a> {
    /// Run id.
    pub run_id: &'a str,
    /// The run's scenario.
    pub scenario: &'a formation_config::Scenario,
    /// Controller variant.
    pub variant: &'a str,
    /// `lockstep` or `realtime`.
    pub mode: &'a str,
}

/// Why the export cannot listen or start.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// `--zenoh-listen` refused: an endpoint, the `--auth` file, a port in use.
    #[cfg(feature = "multihost")]
    #[error("--zenoh-listen: {0}")]
    Listen(formation_net::export::ExportError),
    /// The export thread could not open the run's services or start.
    #[cfg(feature = "multihost")]
    #[error("{0}")]
    Start(formation_net::export::ExportError),
    /// `--zenoh-listen` in a build without Zenoh.
    #[error("{}", NO_ZENOH)]
    NoZenoh,
}

#[cfg(feature = "multihost")]
mod on {
    use super::{ExportArgs, ExportError, Facts};
    use crate::record::{Cadence, Sink, Step};
    use formation_net::export::{Export, ExportConfig, Listening, RunFacts, StepFeed};
    use std::path::Path;

    /// The export with its endpoints bound, before the run's services exist.
    pub struct Opened(Listening);

    /// The running export: ended by [`Running::finish`]; dropped without it (a run that returns
    /// on an error), stopped after a last drain of the run's services.
    pub struct Running(Export);

    /// The export as an output of the recorder: every step, handed over without waiting.
    struct ExportSink(StepFeed);

    impl Sink for ExportSink {
        fn cadence(&self) -> Cadence {
            Cadence::Every
        }

        fn step(&mut self, s: &Step<'_>) -> std::io::Result<()> {
            self.0.offer(s.reference, s.truths, s.commands);
            Ok(())
        }

        /// The export ends with [`Running::finish`], before the recorder does.
        fn finish(self: Box<Self>) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Running {
        /// The recorder's sink that hands every step it records to the export.
        pub fn sink(&self) -> Box<dyn Sink> {
            Box::new(ExportSink(self.0.feed()))
        }

        /// Ends the export with a run that recorded `recorded` steps, before its role processes
        /// stop (bounded by `formation_net::export::END_BOUND`); prints how it went on stderr and
        /// returns it for `summary.json` `export`.
        pub fn finish(self, recorded: u64) -> serde_json::Value {
            let r = self.0.finish(recorded);
            eprintln!("{}", r.line());
            serde_json::to_value(&r).expect("JSON of plain values")
        }
    }

    /// Binds the endpoints of `--zenoh-listen` (`None` without it); an endpoint refused, a
    /// missing or unsafe `--auth` file or a port in use is an error naming it (exit 2).
    pub fn open(
        args: &ExportArgs,
        auth: Option<&Path>,
        prefix: &str,
        f: &Facts,
    ) -> Result<Option<Opened>, ExportError> {
        if !args.enabled() {
            return Ok(None);
        }
        let cfg = ExportConfig {
            facts: RunFacts {
                run_id: f.run_id.to_string(),
                scenario: f.scenario.name.clone(),
                variant: f.variant.to_string(),
                mode: f.mode.to_string(),
                n_agents: f.scenario.n_agents(),
                dt_s: f.scenario.simulation.dt_s,
                steps: f.scenario.n_steps(),
            },
            prefix: prefix.to_string(),
            listen: args.zenoh_listen.clone(),
            auth: auth.map(Path::to_path_buf),
        };
        Listening::open(cfg)
            .map(|l| Some(Opened(l)))
            .map_err(ExportError::Listen)
    }

    impl Opened {
        /// Starts reading the run's services (they must exist).
        pub fn start(self) -> Result<Running, ExportError> {
            self.0.start().map(Running).map_err(ExportError::Start)
        }
    }
}

#[cfg(not(feature = "multihost"))]
mod on {
    use super::{ExportArgs, ExportError, Facts};
    use std::path::Path;

    /// Never built without the `multihost` feature.
    pub enum Opened {}

    /// Never built without the `multihost` feature.
    pub enum Running {}

    /// `--zenoh-listen` is refused: this build has no Zenoh.
    pub fn open(
        args: &ExportArgs,
        _: Option<&Path>,
        _: &str,
        _: &Facts,
    ) -> Result<Option<Opened>, ExportError> {
        if args.enabled() {
            return Err(ExportError::NoZenoh);
        }
        Ok(None)
    }

    impl Opened {
        /// Unreachable.
        pub fn start(self) -> Result<Running, ExportError> {
            match self {}
        }
    }

    impl Running {
        /// Unreachable.
        pub fn sink(&self) -> Box<dyn crate::record::Sink> {
            match *self {}
        }

        /// Unreachable.
        pub fn finish(self, _: u64) -> serde_json::Value {
            match self {}
        }
    }
}

/// The refusal of `--zenoh-listen` by a build without the `multihost` feature.
#[cfg_attr(feature = "multihost", allow(dead_code))]
pub const NO_ZENOH: &str = "--zenoh-listen: this formation was built without the `multihost` \
     feature (Zenoh); build it with default features to export a run over the network";

pub use on::{open, Opened, Running};

#[cfg(test)]
mod tests {
    use super::*;

    fn facts_of(s: &formation_config::Scenario) -> Facts<'_> {
        Facts {
            run_id: "t1",
            scenario: s,
            variant: "proposed",
            mode: "lockstep",
        }
    }

    #[test]
    fn without_the_flag_nothing_is_opened() {
        let s = formation_config::Scenario::paper();
        let none = ExportArgs {
            zenoh_listen: vec![],
        };
        assert!(!none.enabled());
        assert!(open(&none, None, "fmt1_", &facts_of(&s)).unwrap().is_none());
    }

    #[test]
    fn listening_beyond_loopback_without_auth_is_refused_naming_the_flag() {
        let s = formation_config::Scenario::paper();
        let wide = ExportArgs {
            zenoh_listen: vec!["tcp/0.0.0.0:7448".into()],
        };
        let e = open(&wide, None, "fmt1_", &facts_of(&s))
            .err()
            .expect("refused")
            .to_string();
        assert!(e.starts_with("--zenoh-listen"), "{e}");
        #[cfg(feature = "multihost")]
        assert!(e.contains("requires authentication"), "{e}");
        #[cfg(not(feature = "multihost"))]
        assert_eq!(e, NO_ZENOH);
    }
}
