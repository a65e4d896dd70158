//! Shared command-line plumbing: exit codes, defaults parsed by clap, whole-number arguments, the
//! `--set path=value` overrides, and loading and validating scenarios (exit code 2 on bad input).
//!
//! Every exit code of every subcommand is listed in docs/cli.md.

use formation_config::scenario::validate::validate;
use formation_config::Scenario;

use formation_config::scenario::validate::ValidationErrors;
use std::path::PathBuf;

/// Exit code for invalid input (bad scenario, bad arguments); clap's own usage errors use it too.
pub const EXIT_INVALID: u8 = 2;
/// Exit code when the command ran to its end and wrote its outputs, but its result is a failure:
/// `check` found a FAIL verdict, `sim`/`run` diverged.
pub const EXIT_RESULT_FAILED: u8 = 3;
/// Exit code after Ctrl-C (128 + SIGINT).
pub const EXIT_INTERRUPTED: u8 = 130;
/// Exit code of a role process (`formation node`) that could not make one of its ports because
/// another process still holds it (an agent's predecessor that is not gone yet): try again later
/// (EX_TEMPFAIL of sysexits.h). The supervision waits for the predecessor to be fenced and starts
/// the agent again, without counting it against `runtime.max_restarts` (docs/failures.md).
pub const EXIT_PORT_HELD: u8 = 75;

/// The arguments of subcommand `name` with every default applied by clap, exactly as if the
/// subcommand had been given with no argument (bare `formation` is `formation run`).
pub fn defaults<T: clap::Args + clap::FromArgMatches>(name: &'static str) -> T {
    let command = T::augment_args(clap::Command::new(name));
    let matches = command
        .try_get_matches_from([name])
        .unwrap_or_else(|e| e.exit());
    T::from_arg_matches(&matches).unwrap_or_else(|e| e.exit())
}

/// Value parser of a whole-number argument (counts, ids, microseconds). Negative values reach it
/// (the argument sets `allow_negative_numbers`) so that the error names the argument and says what
/// is wrong instead of clap's `unexpected argument '-3'`.
pub fn whole_number<T: TryFrom<u64>>(text: &str) -> Result<T, NumberError> {
    match text.trim().parse::<i128>() {
        Ok(v) if v < 0 => Err(NumberError::Negative(v)),
        Ok(v) => u64::try_from(v)
            .ok()
            .and_then(|v| T::try_from(v).ok())
            .ok_or(NumberError::TooLarge(v)),
        Err(_) => Err(NumberError::NotANumber(text.to_string())),
    }
}

/// Why a whole-number argument is refused ([`whole_number`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NumberError {
    /// Below zero.
    #[error("{0} is negative: expected a whole number >= 0")]
    Negative(i128),
    /// Above what the argument's type holds.
    #[error("{0} is too large")]
    TooLarge(i128),
    /// Not a whole number at all (the text given).
    #[error("'{0}' is not a whole number: expected a whole number >= 0")]
    NotANumber(String),
}

/// Why `--foxglove ADDR` is refused ([`foxglove_addr`]).
#[derive(Debug, thiserror::Error)]
pub enum AddrError {
    /// This build has no Foxglove server.
    #[error("{}", crate::record::NO_FOXGLOVE)]
    NoFoxglove,
    /// The address does not resolve (the text given and the resolver's error).
    #[error(
        "'{text}': {source}; expected HOST:PORT, e.g. 127.0.0.1:8765 (port 0 picks a free one)"
    )]
    Resolve {
        /// The address given.
        text: String,
        /// The resolver's error.
        source: std::io::Error,
    },
    /// The address resolves to nothing.
    #[error("'{0}': resolves to no address; expected HOST:PORT, e.g. 127.0.0.1:8765 (port 0 picks a free one)")]
    NoAddress(String),
}

/// Value parser of `--foxglove ADDR`: `HOST:PORT` (a name is resolved; port 0 picks a free one).
pub fn foxglove_addr(text: &str) -> Result<std::net::SocketAddr, AddrError> {
    if !cfg!(feature = "foxglove") {
        return Err(AddrError::NoFoxglove);
    }
    use std::net::ToSocketAddrs;
    text.to_socket_addrs()
        .map_err(|source| AddrError::Resolve {
            text: text.to_string(),
            source,
        })?
        .next()
        .ok_or_else(|| AddrError::NoAddress(text.to_string()))
}

/// Which elements of an array a `--set` path segment selects.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Index {
    /// `[k]`, 0-based (TOML arrays).
    At(usize),
    /// `[*]`: every element.
    Every,
}

/// One segment of a `--set` path: a key, optionally indexed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Segment {
    /// The key (`[A-Za-z_][A-Za-z0-9_]*`).
    pub key: String,
    /// The index, if any.
    pub index: Option<Index>,
}

/// A parsed `--set path=value`.
#[derive(Debug, Clone, PartialEq)]
pub struct Override {
    /// The path, e.g. `agents[*].delay.base_s`.
    pub path: Vec<Segment>,
    /// The value (one TOML value).
    pub value: toml::Value,
}

/// What a `--set` path looks like.
const PATH_GRAMMAR: &str =
    "key(.key)* where a key is [A-Za-z_][A-Za-z0-9_]* optionally followed by \
                            one index [k] (0-based) or [*] (every element)";

/// Why a `--set` path is malformed (`PATH_GRAMMAR`); `part` is the offending segment.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PathError {
    /// Nothing before the `=`.
    #[error("the path is empty")]
    Empty,
    /// A segment that does not start with a key.
    #[error("'{0}' does not start with a key")]
    NoKey(String),
    /// What follows the key is not one `[k]` or `[*]`.
    #[error("'{part}': '{rest}' is not one index [k] or [*]")]
    NotOneIndex {
        /// The segment.
        part: String,
        /// What follows its key.
        rest: String,
    },
    /// An index beyond `usize`.
    #[error("'{part}': index {inner} is too large")]
    IndexTooLarge {
        /// The segment.
        part: String,
        /// The index as written.
        inner: String,
    },
    /// An index that is neither a whole number nor `*`.
    #[error("'{part}': index '{inner}' is not a whole number >= 0 or *")]
    BadIndex {
        /// The segment.
        part: String,
        /// The index as written.
        inner: String,
    },
}

/// Why a `--set` path does not lead to a field of the scenario; `at` names where it stopped.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PlaceError {
    /// A key below a value that is not a table.
    #[error("{at} is not a table, it has no field '{key}'")]
    NotATable {
        /// The value ("the scenario" at the root).
        at: String,
        /// The key asked for.
        key: String,
    },
    /// A key the table does not have.
    #[error("{at} has no field '{key}'")]
    NoField {
        /// The table ("the scenario" at the root).
        at: String,
        /// The key asked for.
        key: String,
    },
    /// An index on a value that is not an array.
    #[error("{0} is not an array")]
    NotAnArray(String),
    /// An index past the end: the element and how many there are.
    #[error("{element} does not exist: {extent}")]
    NoElement {
        /// The element asked for, e.g. `agents[7] (agent 8)`.
        element: String,
        /// How many elements there are.
        extent: String,
    },
    /// `[*]` on an empty array.
    #[error("{0}[*]: {0} is empty")]
    EmptyArray(String),
}

/// Why a `--set path=value` is refused; `set` is the argument as given.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OverrideError {
    /// The argument holds a line break.
    #[error("--set {set:?}: contains a line break; give one path=value per --set")]
    LineBreak {
        /// The argument.
        set: String,
    },
    /// No `=`.
    #[error("--set {set:?}: expected path=value")]
    NoEquals {
        /// The argument.
        set: String,
    },
    /// A malformed path.
    #[error("--set {set:?}: {source}; expected {grammar}", grammar = PATH_GRAMMAR)]
    Path {
        /// The argument.
        set: String,
        /// What is wrong with the path.
        source: PathError,
    },
    /// Nothing after the `=`.
    #[error("--set {set:?}: the value is missing")]
    NoValue {
        /// The argument.
        set: String,
    },
    /// The value is not one TOML value.
    #[error("--set {set:?}: the value '{text}' is not one TOML value: {message}")]
    Value {
        /// The argument.
        set: String,
        /// The value as given.
        text: String,
        /// The TOML parser's message.
        message: String,
    },
    /// The path does not lead to a field.
    #[error("--set {set:?}: {source}")]
    Place {
        /// The argument.
        set: String,
        /// Where the path stopped.
        source: PlaceError,
    },
    /// The scenario could not be turned into a TOML tree (the encoder's message).
    #[error("{0}")]
    Encode(String),
    /// The scenario with the overrides is not a scenario any more (the decoder's error).
    #[error("--set: {0}")]
    Decode(toml::de::Error),
}

/// Parses one `--set` argument. It must be `path=value` exactly (spaces may surround the `=`): the
/// path follows [`PATH_GRAMMAR`], the value is one TOML value with nothing after it, on one line.
pub fn parse_override(set: &str) -> Result<Override, OverrideError> {
    let owned = || set.to_string();
    if set.contains(['\n', '\r']) {
        return Err(OverrideError::LineBreak { set: owned() });
    }
    let (path, value) = set
        .split_once('=')
        .ok_or_else(|| OverrideError::NoEquals { set: owned() })?;
    // Spaces may surround the `=` (as in TOML), nowhere else in the path.
    let path =
        parse_path(path.trim_end_matches([' ', '\t'])).map_err(|source| OverrideError::Path {
            set: owned(),
            source,
        })?;
    let text = value.trim_matches([' ', '\t']);
    if text.is_empty() {
        return Err(OverrideError::NoValue { set: owned() });
    }
    let value = serde::Deserialize::deserialize(toml::de::ValueDeserializer::new(text)).map_err(
        |e: toml::de::Error| OverrideError::Value {
            set: owned(),
            text: text.to_string(),
            message: e.message().to_string(),
        },
    )?;
    Ok(Override { path, value })
}

fn parse_path(path: &str) -> Result<Vec<Segment>, PathError> {
    if path.is_empty() {
        return Err(PathError::Empty);
    }
    path.split('.').map(parse_segment).collect()
}

fn parse_segment(part: &str) -> Result<Segment, PathError> {
    let key_len = part
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .unwrap_or(part.len());
    let (key, rest) = part.split_at(key_len);
    if key.is_empty() || key.starts_with(|c: char| c.is_ascii_digit()) {
        return Err(PathError::NoKey(part.to_string()));
    }
    let index = if rest.is_empty() {
        None
    } else {
        let inner = rest
            .strip_prefix('[')
            .and_then(|r| r.strip_suffix(']'))
            .filter(|inner| !inner.contains(['[', ']']))
            .ok_or_else(|| PathError::NotOneIndex {
                part: part.to_string(),
                rest: rest.to_string(),
            })?;
        if inner == "*" {
            Some(Index::Every)
        } else if !inner.is_empty() && inner.bytes().all(|b| b.is_ascii_digit()) {
            Some(Index::At(inner.parse().map_err(|_| {
                PathError::IndexTooLarge {
                    part: part.to_string(),
                    inner: inner.to_string(),
                }
            })?))
        } else {
            return Err(PathError::BadIndex {
                part: part.to_string(),
                inner: inner.to_string(),
            });
        }
    };
    Ok(Segment {
        key: key.to_string(),
        index,
    })
}

/// How a message names element `k` of the array at `path`: `agents[k]` also says which agent it
/// is (agent ids are 1-based everywhere else).
fn element(path: &str, k: usize) -> String {
    if path == "agents" {
        format!("agents[{k}] (agent {})", k + 1)
    } else {
        format!("{path}[{k}]")
    }
}

/// Sets `value` at `path` below `node`; `done` names `node` in messages ("" at the root).
fn set_at(
    node: &mut toml::Value,
    path: &[Segment],
    value: &toml::Value,
    done: &str,
) -> Result<(), PlaceError> {
    let Some((seg, rest)) = path.split_first() else {
        *node = value.clone();
        return Ok(());
    };
    let parent = if done.is_empty() {
        "the scenario"
    } else {
        done
    };
    let here = if done.is_empty() {
        seg.key.clone()
    } else {
        format!("{done}.{}", seg.key)
    };
    let child = node
        .as_table_mut()
        .ok_or_else(|| PlaceError::NotATable {
            at: parent.to_string(),
            key: seg.key.clone(),
        })?
        .get_mut(&seg.key)
        .ok_or_else(|| PlaceError::NoField {
            at: parent.to_string(),
            key: seg.key.clone(),
        })?;
    let Some(index) = seg.index else {
        return set_at(child, rest, value, &here);
    };
    let items = child
        .as_array_mut()
        .ok_or_else(|| PlaceError::NotAnArray(here.clone()))?;
    let len = items.len();
    match index {
        Index::At(k) => {
            let item = items.get_mut(k).ok_or_else(|| {
                let extent = if here == "agents" {
                    format!("the scenario has {len} agents: agents[0] .. agents[{}] (0-based, agents 1 .. {len})", len.saturating_sub(1))
                } else {
                    format!("{here} has {len} elements (0-based)")
                };
                PlaceError::NoElement {
                    element: element(&here, k),
                    extent,
                }
            })?;
            set_at(item, rest, value, &element(&here, k))
        }
        Index::Every => {
            if len == 0 {
                return Err(PlaceError::EmptyArray(here));
            }
            for (k, item) in items.iter_mut().enumerate() {
                set_at(item, rest, value, &element(&here, k))?;
            }
            Ok(())
        }
    }
}

/// Applies `--set path=value` overrides (TOML paths such as `controller.position.k_p`,
/// `agents[2].delay.base_s` (0-based: agent 3) or `agents[*].delay.base_s` (every agent); values
/// in TOML syntax) to a scenario. Anything but `path=value` exactly is rejected, naming it.
pub fn apply_overrides(s: Scenario, sets: &[String]) -> Result<Scenario, OverrideError> {
    if sets.is_empty() {
        return Ok(s);
    }
    let mut root = toml::Value::try_from(&s).map_err(|e| OverrideError::Encode(e.to_string()))?;
    for set in sets {
        let o = parse_override(set)?;
        set_at(&mut root, &o.path, &o.value, "").map_err(|source| OverrideError::Place {
            set: set.clone(),
            source,
        })?;
    }
    root.try_into().map_err(OverrideError::Decode)
}

/// Why the scenario or the arguments of a runner (`sim`, `run`, `check`) are refused: bad input,
/// exit 2. Each names the argument or file.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// The scenario cannot be loaded (its name or file, and why).
    #[error("{0}")]
    Load(#[from] formation_config::scenario::LoadError),
    /// A `--set` override is refused.
    #[error("{0}")]
    Override(#[from] OverrideError),
    /// The scenario `name` after the overrides breaks its rules: every broken rule, one a line.
    #[error("scenario '{name}' is invalid:\n{}", print_lines(&errors.0))]
    Invalid {
        /// The scenario's name or file as given.
        name: String,
        /// The broken rules.
        errors: ValidationErrors,
    },
    /// The scenario with the runtime flags and the `--events` file breaks its rules.
    #[error("the scenario with its runtime settings and events is invalid:\n{}", print_lines(&.0 .0))]
    InvalidWithEvents(ValidationErrors),
    /// `--variant` names no variant.
    #[error("unknown variant '{0}' (expected proposed, no-rbfnn or unconstrained)")]
    Variant(String),
    /// The `--events` file cannot be read or holds something else than events.
    #[error("--events {}: {source}", path.display())]
    Events {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        source: EventsError,
    },
    /// `--ros2` or `--record rosbag2` in a build without ROS 2.
    #[error("{}", crate::record::NO_ROS2)]
    NoRos2,
    /// `--ros2` in an environment that is no valid ROS 2 one.
    #[cfg(feature = "ros2")]
    #[error("--ros2: {0}")]
    Ros2Env(crate::record::ros2::EnvError),
}

/// Loads a scenario, applies the overrides, validates; an [`InputError`] (exit 2) naming what is
/// wrong otherwise.
pub fn load_with_overrides(name: Option<&str>, sets: &[String]) -> Result<Scenario, InputError> {
    let name = name.unwrap_or("paper");
    let s = apply_overrides(Scenario::load(name)?, sets)?;
    validate(&s).map_err(|errors| InputError::Invalid {
        name: name.to_string(),
        errors,
    })?;
    Ok(s)
}

/// Most errors printed for one input; the rest are counted.
pub const MAX_PRINTED_ERRORS: usize = 20;

/// The lines of a list of validation errors, indented: the first [`MAX_PRINTED_ERRORS`], then
/// how many more.
pub fn error_lines<T: std::fmt::Display>(errors: &[T]) -> Vec<String> {
    let mut out: Vec<String> = errors
        .iter()
        .take(MAX_PRINTED_ERRORS)
        .map(|e| format!("  {e}"))
        .collect();
    if errors.len() > MAX_PRINTED_ERRORS {
        out.push(format!(
            "  ... and {} more errors ({} in all)",
            errors.len() - MAX_PRINTED_ERRORS,
            errors.len()
        ));
    }
    out
}

/// [`error_lines`] as one text (no line break at its end).
pub fn print_lines<T: std::fmt::Display>(errors: &[T]) -> String {
    error_lines(errors).join("\n")
}

/// Parses a variant name; [`InputError::Variant`] (exit 2) on an unknown one.
pub fn parse_variant(name: &str) -> Result<formation_config::Variant, InputError> {
    formation_config::Variant::parse(name).ok_or_else(|| InputError::Variant(name.to_string()))
}

/// What every runner (`sim`, `run`) takes: scenario, variant, output directory and overrides.
#[derive(clap::Args, Debug, Clone)]
pub struct RunnerArgs {
    /// Scenario: `paper` (default), `paper-exact`, or a TOML file.
    pub scenario: Option<String>,
    /// Controller variant: proposed, no-rbfnn, unconstrained.
    #[arg(long, default_value = "proposed")]
    pub variant: String,
    /// Output directory (default: out/<scenario>-<variant>[-<mode>]).
    #[arg(long)]
    pub out: Option<std::path::PathBuf>,
    /// Override a scenario parameter, e.g. `--set controller.position.k_p=1.5`,
    /// `--set 'agents[2].delay.base_s=0.04'` (0-based index: agent 3) or
    /// `--set 'agents[*].delay.base_s=0.04'` (every agent); repeatable.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub sets: Vec<String>,
    /// Add the events of FILE to the scenario's timeline: a TOML file of `[[events]]`, or the
    /// `events.jsonl` of a live run (record and replay: a lockstep run replays it bit for bit).
    #[arg(long, value_name = "FILE")]
    pub events: Option<std::path::PathBuf>,
    /// What to do when an agent process dies or hangs (`runtime.restart`): never (stop the run)
    /// or on-failure (start a new one; plant and leader are never restarted).
    #[arg(long, value_enum)]
    pub restart: Option<RestartArg>,
    /// Most restarts of one agent (`runtime.max_restarts`).
    #[arg(long, value_parser = crate::cli::whole_number::<u32>, allow_negative_numbers = true)]
    pub max_restarts: Option<u32>,
    /// A run without progress for this long has a hung process, ms (`runtime.stall_timeout_ms`;
    /// 0 disables).
    #[arg(long, value_parser = crate::cli::whole_number::<u64>, allow_negative_numbers = true)]
    pub stall_timeout_ms: Option<u64>,
    /// What a restarted agent starts from (`runtime.restart_state`).
    #[arg(long, value_enum)]
    pub restart_state: Option<RestartStateArg>,
    /// Also record in this format: `mcap` writes DIR/run.mcap (every output step of every agent
    /// and the injections, JSON with JSON Schemas; opens in Foxglove; docs/formats.md), `rosbag2`
    /// writes DIR/rosbag2/ for `ros2 bag` (docs/ros2.md).
    #[arg(long, value_enum, value_name = "FORMAT", value_delimiter = ',')]
    pub record: Vec<crate::record::Format>,
    /// Serve the run live to Foxglove on ADDR (default 127.0.0.1:8765; port 0 picks a free port;
    /// the address is printed on stderr): the 3D scene of the swarm, per-agent plot channels and
    /// the events, on Foxglove's WebSocket protocol (docs/foxglove.md). Put it after SCENARIO.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8765", value_parser = foxglove_addr)]
    pub foxglove: Option<std::net::SocketAddr>,
    /// With --foxglove: wait up to S seconds for a viewer to connect before the run starts (a
    /// lockstep run of the paper scenario lasts a few seconds of wall time).
    #[arg(long, value_name = "S", requires = "foxglove", default_value_t = 0.0)]
    pub foxglove_wait: f64,
    /// Publish the run on ROS 2 topics over DDS: each quadrotor's pose, /tf, markers, the
    /// reference, the events and /clock on simulation time, in domain ROS_DOMAIN_ID, discovered on
    /// this machine only unless ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET (docs/ros2.md).
    #[arg(long)]
    pub ros2: bool,
    /// With --ros2: wait up to S seconds for a subscriber of the pose topics before the run starts.
    #[arg(long, value_name = "S", requires = "ros2", default_value_t = 0.0)]
    pub ros2_wait: f64,
    /// Print the summary as JSON on standard output (the content of DIR/summary.json) instead of
    /// the table; everything else goes to standard error.
    #[arg(long)]
    pub json: bool,
}

/// `--restart`.
#[derive(clap::ValueEnum, Debug, Clone, Copy)]
pub enum RestartArg {
    /// Stop the run.
    Never,
    /// Start a new agent process.
    OnFailure,
}

/// `--restart-state`.
#[derive(clap::ValueEnum, Debug, Clone, Copy)]
pub enum RestartStateArg {
    /// The last checkpoint, replayed.
    Warm,
    /// A fresh controller.
    Cold,
}

impl RunnerArgs {
    /// The live view's options of `--foxglove` and `--foxglove-wait`.
    pub fn live_options(&self) -> Option<crate::record::LiveOptions> {
        self.foxglove.map(|addr| crate::record::LiveOptions {
            addr,
            wait_s: self.foxglove_wait.max(0.0),
        })
    }

    /// The options of `--ros2` and `--ros2-wait`.
    pub fn ros2_options(&self) -> Option<crate::record::Ros2Options> {
        self.ros2.then(|| crate::record::Ros2Options {
            wait_s: self.ros2_wait.max(0.0),
        })
    }

    /// `--ros2` and `--record rosbag2` need the feature `ros2`; `--ros2` a valid ROS 2
    /// environment (`ROS_DOMAIN_ID`, discovery range). An [`InputError`] (exit 2) otherwise.
    fn check_ros2(&self) -> Result<(), InputError> {
        let wanted = self.ros2 || self.record.contains(&crate::record::Format::Rosbag2);
        if wanted && !cfg!(feature = "ros2") {
            return Err(InputError::NoRos2);
        }
        #[cfg(feature = "ros2")]
        if self.ros2 {
            crate::record::ros2::env_options().map_err(InputError::Ros2Env)?;
        }
        Ok(())
    }

    /// The validated scenario (after the overrides, the runtime flags and the events file) and the
    /// variant; an [`InputError`] (exit 2) naming what is wrong otherwise.
    pub fn load(&self) -> Result<(Scenario, formation_config::Variant), InputError> {
        use formation_config::scenario::events::{RestartPolicy, RestartState};
        self.check_ros2()?;
        let mut scenario = load_with_overrides(self.scenario.as_deref(), &self.sets)?;
        let rt = &mut scenario.runtime;
        if let Some(r) = self.restart {
            rt.restart = match r {
                RestartArg::Never => RestartPolicy::Never,
                RestartArg::OnFailure => RestartPolicy::OnFailure,
            };
        }
        if let Some(m) = self.max_restarts {
            rt.max_restarts = m;
        }
        if let Some(t) = self.stall_timeout_ms {
            rt.stall_timeout_ms = t;
        }
        if let Some(s) = self.restart_state {
            rt.restart_state = match s {
                RestartStateArg::Warm => RestartState::Warm,
                RestartStateArg::Cold => RestartState::Cold,
            };
        }
        if let Some(path) = &self.events {
            let mut events = read_events(path).map_err(|source| InputError::Events {
                path: path.clone(),
                source,
            })?;
            scenario.events.append(&mut events);
        }
        validate(&scenario).map_err(InputError::InvalidWithEvents)?;
        Ok((scenario, parse_variant(&self.variant)?))
    }
}

/// Most events one `--events` file may hold ([`formation_config::scenario::validate::MAX_EVENTS`],
/// the limit of a whole timeline).
pub const MAX_EVENTS_PER_FILE: usize = formation_config::scenario::validate::MAX_EVENTS;

/// Largest `--events` file read, bytes (a line of `events.jsonl` is ~400 bytes).
const MAX_EVENTS_FILE_BYTES: u64 = 4 << 20;

/// Why an `--events` file is refused ([`read_events`]).
#[derive(Debug, thiserror::Error)]
pub enum EventsError {
    /// The file cannot be read.
    #[error("{0}")]
    Read(#[from] std::io::Error),
    /// The file is larger than `MAX_EVENTS_FILE_BYTES`.
    #[error("larger than {} MiB; a file holds at most {MAX_EVENTS_PER_FILE} events", MAX_EVENTS_FILE_BYTES >> 20)]
    TooLarge,
    /// The file holds this many events or more, over [`MAX_EVENTS_PER_FILE`].
    #[error(
        "{0} events or more; a file holds at most {MAX_EVENTS_PER_FILE} (and a timeline as many)"
    )]
    TooMany(usize),
    /// A TOML file that is no `[[events]]` list.
    #[error("{0}")]
    Toml(#[from] toml::de::Error),
    /// A JSON line (1-based) that is no event.
    #[error("line {line}: {source}")]
    Json {
        /// The line, 1-based.
        line: usize,
        /// The JSON reader's error.
        source: serde_json::Error,
    },
    /// A JSON line (1-based) whose event has no time.
    #[error("line {line}: an event needs `at_s` (its time, s); got {text}")]
    NoTime {
        /// The line, 1-based.
        line: usize,
        /// The line's text.
        text: String,
    },
}

/// The events of a file: TOML with `[[events]]`, or JSON lines (a live run's `events.jsonl`, whose
/// accepted injections carry their event as `"scenario_event"` and whose refused requests,
/// `"event": "rejected"`, are skipped), or JSON lines of bare events. A line that is neither (an
/// event without `at_s`) is an error naming the line; so is a file of more than
/// [`MAX_EVENTS_PER_FILE`] events.
pub fn read_events(
    path: &std::path::Path,
) -> Result<Vec<formation_config::scenario::events::Event>, EventsError> {
    use formation_config::scenario::events::Event;
    use std::io::Read;
    let mut text = String::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(MAX_EVENTS_FILE_BYTES + 1).read_to_string(&mut text))?;
    if text.len() as u64 > MAX_EVENTS_FILE_BYTES {
        return Err(EventsError::TooLarge);
    }
    let is_toml = path.extension().is_some_and(|x| x == "toml");
    if is_toml {
        #[derive(serde::Deserialize)]
        struct File {
            events: Vec<Event>,
        }
        let events = toml::from_str::<File>(&text).map(|f| f.events)?;
        if events.len() > MAX_EVENTS_PER_FILE {
            return Err(EventsError::TooMany(events.len()));
        }
        return Ok(events);
    }
    let mut out = Vec::new();
    for (k, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let json = |source| EventsError::Json {
            line: k + 1,
            source,
        };
        let v: serde_json::Value = serde_json::from_str(line).map_err(json)?;
        let ev = match v.get("scenario_event") {
            Some(e) => e.clone(),
            None if v.get("event").and_then(|e| e.as_str()) == Some("rejected") => continue,
            None => v,
        };
        if ev.get("at_s").is_none_or(|t| t.is_null()) {
            return Err(EventsError::NoTime {
                line: k + 1,
                text: line.to_string(),
            });
        }
        if out.len() == MAX_EVENTS_PER_FILE {
            return Err(EventsError::TooMany(out.len() + 1));
        }
        out.push(serde_json::from_value::<Event>(ev).map_err(json)?);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn event_times_read_back_from_json_lines_are_the_exact_f64_that_was_written() {
        // `t = step * dt` is not always the shortest decimal (1646 * 0.001 = 1.6460000000000001);
        // a replayed events.jsonl and `inject --json` must give back those exact bits.
        let path =
            std::env::temp_dir().join(format!("formation-roundtrip-{}.jsonl", std::process::id()));
        // 1000 steps (the most one file holds) across 5 s, 1646 among them.
        let times: Vec<f64> = (0..1000u32).map(|j| f64::from(1 + 5 * j) * 0.001).collect();
        let lines: String = times
            .iter()
            .map(|t| {
                format!(
                    "{}\n",
                    serde_json::json!({"at_s": t, "kind": "crash", "agent": 1, "down_s": 0.5})
                )
            })
            .collect();
        std::fs::write(&path, lines).unwrap();
        let events = read_events(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        assert_eq!(events.len(), times.len());
        for (e, t) in events.iter().zip(&times) {
            assert_eq!(e.at_s.to_bits(), t.to_bits(), "{t} read back as {}", e.at_s);
        }
    }

    fn events_file(
        tag: &str,
        text: &str,
    ) -> Result<Vec<formation_config::scenario::events::Event>, String> {
        let path =
            std::env::temp_dir().join(format!("formation-ev-{tag}-{}.jsonl", std::process::id()));
        std::fs::write(&path, text).unwrap();
        let r = read_events(&path).map_err(|e| e.to_string());
        let _ = std::fs::remove_file(&path);
        r
    }

    #[test]
    fn an_event_line_without_at_s_is_an_error_naming_the_line_and_refused_requests_are_skipped() {
        let ok = r#"{"at_s": 0.5, "kind": "crash", "agent": 1, "down_s": 0.5}"#;
        let rejected = r#"{"event": "rejected", "nonce": 1, "error": "x"}"#;
        let missing = r#"{"kind": "crash", "agent": 1, "down_s": 0.5}"#;
        assert_eq!(
            events_file("ok", &format!("{ok}\n{rejected}\n"))
                .unwrap()
                .len(),
            1
        );
        let e = events_file("missing", &format!("{ok}\n\n{missing}\n")).unwrap_err();
        assert!(e.contains("line 3") && e.contains("at_s"), "{e}");
    }

    #[test]
    fn an_events_file_holds_at_most_the_cap_and_printed_errors_are_capped() {
        let line = r#"{"at_s": 0.5, "kind": "link_down", "agents": [1, 2]}"#;
        let text = format!("{line}\n").repeat(MAX_EVENTS_PER_FILE + 1);
        let e = events_file("cap", &text).unwrap_err();
        assert!(e.contains(&MAX_EVENTS_PER_FILE.to_string()), "{e}");
        let errors: Vec<String> = (0..829).map(|k| format!("error {k}")).collect();
        let lines = error_lines(&errors);
        assert_eq!(lines.len(), MAX_PRINTED_ERRORS + 1);
        assert!(lines.last().unwrap().contains("809 more"), "{lines:?}");
    }

    fn set(s: Scenario, sets: &[&str]) -> Result<Scenario, String> {
        apply_overrides(s, &sets.iter().map(|x| x.to_string()).collect::<Vec<_>>())
            .map_err(|e| e.to_string())
    }

    fn rejected(arg: &str) -> String {
        let e = set(Scenario::paper(), &[arg]).expect_err(arg);
        assert!(e.contains(&format!("{arg:?}")), "names the argument: {e}");
        e
    }

    #[test]
    fn set_changes_a_nested_field_and_one_agent_by_its_0_based_index() {
        let s = set(
            Scenario::paper(),
            &["controller.position.k_p=1.5", "agents[2].delay.base_s=0.02"],
        )
        .unwrap();
        assert_eq!(s.controller.position.k_p, 1.5);
        assert_eq!(s.agents[2].delay.base_s, 0.02);
        assert_ne!(s.agents[1].delay.base_s, 0.02);
        let s = set(Scenario::paper(), &["vehicle.inertia_kg_m2[1] = 0.03"]).unwrap();
        assert_eq!(s.vehicle.inertia_kg_m2[1], 0.03);
    }

    #[test]
    fn set_with_a_star_index_changes_every_agent() {
        let s = set(Scenario::paper(), &["agents[*].delay.base_s=0.01"]).unwrap();
        assert_eq!(s.n_agents(), 5);
        assert!(s.agents.iter().all(|a| a.delay.base_s == 0.01));
        let s = set(Scenario::paper(), &["agents[*].fault.gamma_final[0]=0.9"]).unwrap();
        assert!(s.agents.iter().all(|a| a.fault.gamma_final[0] == 0.9));
    }

    #[test]
    fn set_rejects_a_malformed_path_naming_the_argument() {
        for arg in [
            "agents[0.delay.base_s=0.1",
            "agents[0]]]].delay.base_s=0.1",
            "agents[0]]]]=0.1",
            "agents[0][1].delay.base_s=0.1",
            "agents[-1].delay.base_s=0.1",
            "agents[1x].delay.base_s=0.1",
            "agents[].delay.base_s=0.1",
            "agents.[0].delay.base_s=0.1",
            "controller..position.k_p=1",
            ".controller.position.k_p=1",
            "controller.position.k_p.=1",
            " controller.position.k_p=1",
            "controller.position.k p=1",
            "=1",
            "controller.position.k_p",
        ] {
            rejected(arg);
        }
    }

    #[test]
    fn set_rejects_a_value_that_is_not_exactly_one_toml_value() {
        for arg in [
            "controller.position.k_p=1.5\nsimulation.duration_s=1",
            "controller.position.k_p=1.5\r",
            "controller.position.k_p=1.5 2",
            "controller.position.k_p=1.5]",
            "controller.position.k_p=1.5 # comment",
            "controller.position.k_p=1.5, 2",
            "controller.position.k_p=",
            "controller.position.k_p=  ",
            "controller.position.k_p=abc",
        ] {
            rejected(arg);
        }
        // One value, surrounded by spaces, is fine; so are arrays and strings.
        let s = set(
            Scenario::paper(),
            &[
                "controller.position.k_p= 1.5 ",
                "metrics.cover_window_s=[10.0, 30.0]",
                "name=\"x\"",
            ],
        )
        .unwrap();
        assert_eq!(s.controller.position.k_p, 1.5);
        assert_eq!(s.metrics.cover_window_s, [10.0, 30.0]);
        assert_eq!(s.name, "x");
    }

    #[test]
    fn set_names_a_missing_field_and_an_agent_out_of_range_with_its_1_based_id() {
        let e = rejected("controller.position.kp=1");
        assert!(e.contains("controller.position has no field 'kp'"), "{e}");
        let e = rejected("agents[7].delay.base_s=0.1");
        assert!(e.contains("agents[7] (agent 8) does not exist"), "{e}");
        assert!(e.contains("5 agents"), "{e}");
        let e = rejected("agents[2].delay.bse_s=0.1");
        assert!(
            e.contains("agents[2] (agent 3).delay has no field 'bse_s'"),
            "{e}"
        );
        let e = rejected("controller.position[0].k_p=1");
        assert!(e.contains("controller.position is not an array"), "{e}");
    }

    #[test]
    fn whole_numbers_reject_negative_values_saying_so() {
        assert_eq!(whole_number::<usize>("3"), Ok(3));
        let e = whole_number::<usize>("-3").unwrap_err().to_string();
        assert!(e.contains("-3 is negative"), "{e}");
        assert!(whole_number::<u32>("1.5").is_err());
        assert!(whole_number::<u32>("99999999999")
            .unwrap_err()
            .to_string()
            .contains("too large"));
    }

    #[test]
    fn defaults_are_the_ones_clap_applies_to_an_empty_command_line() {
        let a: crate::run::RunArgs = defaults("run");
        assert_eq!(a.pin, "auto");
        assert_eq!(a.common.variant, "proposed");
        assert_eq!(a.spin_us, 20);
        assert!(a.common.scenario.is_none() && a.common.sets.is_empty());
    }
}
