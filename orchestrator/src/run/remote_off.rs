//! `formation run` built without the `multihost` feature: no placement options, every process on
//! this machine.

pub use super::remote_error::RemoteError;
use super::spawn::RoleProcess;
use formation_config::node::args::ChildArgs;
use formation_config::protocol::services::Sizing;
use formation_config::Scenario;
use std::path::Path;
use std::time::{Duration, Instant};

/// Where the agents of a lost host would be taken over.
pub const TAKEOVER_HOST: &str = "local";

/// No placement options without the `multihost` feature.
#[derive(clap::Args, Debug, Clone)]
pub struct PlaceArgs {}

impl PlaceArgs {
    /// No `--auth` without the `multihost` feature.
    pub fn auth(&self) -> Option<&Path> {
        None
    }
}

/// Never built.
pub enum Remote {}

/// Never built.
pub enum RemoteRun {}

/// Every run is local.
pub fn connect(_: &PlaceArgs, _: &Scenario) -> Result<Option<Remote>, RemoteError> {
    Ok(None)
}

impl Remote {
    /// Unreachable.
    pub fn prepare(
        self,
        _: &str,
        _: &str,
        _: &Scenario,
        _: &str,
        _: super::HostPacing,
    ) -> Result<RemoteRun, RemoteError> {
        match self {}
    }
}

impl RemoteRun {
    /// Unreachable.
    pub fn attach(&self, _: &str, _: Sizing, _: &Path) -> Result<(), RemoteError> {
        match *self {}
    }
    /// Unreachable.
    pub fn is_remote(&self, _: usize) -> bool {
        match *self {}
    }
    /// Unreachable.
    pub fn describe(&self) -> String {
        match *self {}
    }
    /// Unreachable.
    pub fn spawn(&self, _: usize, _: String, _: &ChildArgs) -> Result<RoleProcess, RemoteError> {
        match *self {}
    }
    /// Unreachable.
    pub fn collect_timing(&self, _: &Path) -> Result<(), RemoteError> {
        match *self {}
    }
    /// Unreachable.
    pub fn clocks_json(&self) -> serde_json::Value {
        match *self {}
    }
    /// Unreachable.
    pub fn fetch_checkpoint(&self, _: usize, _: &Path) -> Result<(), RemoteError> {
        match *self {}
    }
    /// Unreachable.
    pub fn agent_hosts(&self) -> Vec<String> {
        match *self {}
    }
    /// Unreachable.
    pub fn lost_at(&self, _: &str) -> Option<Instant> {
        match *self {}
    }
    /// Unreachable.
    pub fn take_over_host(&self, _: &str) -> Result<Option<Vec<usize>>, RemoteError> {
        match *self {}
    }
    /// Unreachable.
    pub fn restore_checkpoint(
        &self,
        _: usize,
        _: &Path,
        _: u64,
        _: u64,
    ) -> Result<Option<u64>, RemoteError> {
        match *self {}
    }
    /// Unreachable.
    pub fn agents_lost_with(&self, _: &str) -> Vec<usize> {
        match *self {}
    }
    /// Unreachable.
    pub fn lease(&self) -> Duration {
        match *self {}
    }
}
