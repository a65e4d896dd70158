//! `run.mcap` (`formation sim|run --record mcap`): the recorded steps as an MCAP file that Foxglove
//! opens without plugins: JSON messages, each channel with a JSON Schema (`jsonschema` encoding).
//!
//! Channels (agent ids 1-based, as everywhere on the command line):
//!
//! | topic | schema | what |
//! |---|---|---|
//! | `/agent/{id}/state` | `formation.State` | true state P_i, V_i, A_i, Omega_i (the plant's `VehicleState`) |
//! | `/agent/{id}/command` | `formation.Command` | thrust T_iC and torque command U_iAC |
//! | `/agent/{id}/telemetry` | `formation.Telemetry` | the controller's internals (`ControllerTelemetry`) and the formation error |
//! | `/agent/{id}/truth` | `formation.Truth` | what only the plant knows: applied thrust and torque, true faults, uncertainty, disturbance |
//! | `/reference` | `formation.Reference` | virtual leader P_d, target T_g, formation offsets Delta_i0 |
//! | `/events` | `formation.Event` | injections (`formation inject`) at the step they apply |
//!
//! Messages are written at the instants of `trajectory.csv` (every `output_decimation` steps and
//! at a divergence step), with log and publish time t_k = k dt in nanoseconds of simulation time,
//! never the wall clock: a lockstep run and `formation sim` of the same scenario write the same
//! bytes. Floats are written in their shortest round-trip form (as in `trajectory.csv`); a value
//! that is not finite (only at a divergence step, and the barrier widths `c1`, `c2` of the
//! `unconstrained` variant) is `null`.

use super::sink::{event_message, Cadence, Sink, Step};
use formation_config::protocol::wire::{ControlCommand, PlantTruth};
use formation_config::{Scenario, Variant};
use serde::Serialize;
use serde_json::{json, Value};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

/// File name of the recording in the run directory.
pub const FILE_NAME: &str = "run.mcap";

/// MCAP message encoding of every channel (a well-known encoding Foxglove decodes itself).
const MESSAGE_ENCODING: &str = "json";
/// MCAP schema encoding of every schema.
const SCHEMA_ENCODING: &str = "jsonschema";

/// JSON Schema of one field.
fn field_schema(kind: &str, doc: &str) -> Value {
    match kind {
        "integer" => json!({"type": "integer", "description": doc}),
        "number" => json!({"type": "number", "description": doc}),
        "vec3" => json!({
            "type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3,
            "description": doc,
        }),
        "vec3_list" => json!({
            "type": "array",
            "items": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3},
            "description": doc,
        }),
        "string" => json!({"type": "string", "description": doc}),
        other => unreachable!("no schema for field kind {other}"),
    }
}

/// Declares a message struct and its JSON Schema from one list of fields (name, Rust type, schema
/// kind, description with unit), so the two cannot drift apart.
macro_rules! message {
    ($name:ident, $schema_name:literal, $title:literal, { $($field:ident : $ty:ty => $kind:literal, $doc:literal;)* }) => {
        #[doc = $title]
        #[derive(Debug, Clone, Serialize)]
        pub struct $name {
            $(#[doc = $doc] pub $field: $ty,)*
        }

        impl $name {
            /// Name of the schema in the MCAP file.
            pub const SCHEMA_NAME: &'static str = $schema_name;

            /// The JSON Schema of the message.
            pub fn schema() -> Value {
                let mut properties = serde_json::Map::new();
                $(properties.insert(stringify!($field).to_string(), field_schema($kind, $doc));)*
                json!({
                    "$schema": "https://json-schema.org/draft/2020-12/schema",
                    "title": $schema_name,
                    "description": $title,
                    "type": "object",
                    "properties": properties,
                    "required": [$(stringify!($field)),*],
                })
            }
        }
    };
}

message!(StateMsg, "formation.State", "True state of quadrotor i at step k (the plant's VehicleState).", {
    step: u64 => "integer", "simulation step k";
    t: f64 => "number", "simulation time t_k = k dt, s";
    agent: u32 => "integer", "agent id, 1-based";
    position: [f64; 3] => "vec3", "position P_i (inertial frame), m";
    velocity: [f64; 3] => "vec3", "velocity V_i, m/s";
    attitude: [f64; 3] => "vec3", "attitude A_i = [phi, theta, psi], rad";
    rate: [f64; 3] => "vec3", "body rate Omega_i = [p, q, r], rad/s";
});

message!(CommandMsg, "formation.Command", "Command of agent i for step k (ControlCommand without the telemetry).", {
    step: u64 => "integer", "simulation step k";
    t: f64 => "number", "simulation time t_k, s";
    agent: u32 => "integer", "agent id, 1-based";
    thrust_n: f64 => "number", "total thrust command T_iC, eq. (28), N";
    torque_nm: [f64; 3] => "vec3", "torque command U_iAC, eq. (43), N m (before faults and saturation)";
});

message!(TelemetryMsg, "formation.Telemetry", "Controller internals of agent i at step k (ControllerTelemetry) and its formation error.", {
    step: u64 => "integer", "simulation step k";
    t: f64 => "number", "simulation time t_k, s";
    agent: u32 => "integer", "agent id, 1-based";
    formation_error_m: f64 => "number", "formation error |P_i - P_d - Delta_i0|, m";
    tau_s: f64 => "number", "delay tau_i(t_k) the agent applied, s";
    e_p: [f64; 3] => "vec3", "delayed local consensus error e_iP, eq. (8), m";
    e_v: [f64; 3] => "vec3", "delayed local consensus error e_iV, eq. (9), m/s";
    u_p: [f64; 3] => "vec3", "position control U_iP after the limits, eq. (14), m/s^2";
    f_hat: [f64; 3] => "vec3", "RBFNN output F-hat_iP, eq. (11), m/s^2";
    nn_weight_norm: f64 => "number", "Frobenius norm of the RBFNN weights";
    attitude_cmd_raw: [f64; 3] => "vec3", "raw attitude command of eq. (28), rad";
    attitude_cmd: [f64; 3] => "vec3", "filtered attitude command A_iC, rad";
    alpha: [f64; 3] => "vec3", "filtered virtual control alpha_i, rad/s";
    z1: [f64; 3] => "vec3", "attitude error z_i1 = A_i - A_iC, rad";
    z2: [f64; 3] => "vec3", "rate error z_i2 = Omega_i - alpha_i, rad/s";
    blf1: f64 => "number", "barrier value V_i1B, eq. (31)";
    blf2: f64 => "number", "barrier value V_i2B, eq. (40)";
    c1: f64 => "number", "barrier width C_i1, rad (null in the unconstrained variant)";
    c2: f64 => "number", "barrier width C_i2, rad/s (null in the unconstrained variant)";
    gamma_hat: [f64; 3] => "vec3", "Gamma-hat_i (diagonal), eq. (48)";
    delta_hat: [f64; 3] => "vec3", "delta-hat_i, eq. (47), N m";
    d_hat: f64 => "number", "D-hat_iA, eq. (49), rad/s^2";
    model_hat_dev: f64 => "number", "Frobenius norm of Delta F-hat_i - I, eq. (46)";
    e1: [f64; 3] => "vec3", "auxiliary state E_i1, eq. (35)";
    e2: [f64; 3] => "vec3", "auxiliary state E_i2, eq. (50)";
});

message!(TruthMsg, "formation.Truth", "What only the plant knows about quadrotor i at step k (PlantTruth without the state).", {
    step: u64 => "integer", "simulation step k";
    t: f64 => "number", "simulation time t_k, s";
    agent: u32 => "integer", "agent id, 1-based";
    thrust_n: f64 => "number", "thrust applied over [t_k, t_k+1), N";
    torque_applied_nm: [f64; 3] => "vec3", "torque U_iA applied after faults (4) and saturation (3), N m";
    gamma: [f64; 3] => "vec3", "true multiplicative fault Gamma_i (diagonal)";
    delta: [f64; 3] => "vec3", "true additive fault delta_i, N m";
    uncertainty: [f64; 3] => "vec3", "true lumped uncertainty F_iP, m/s^2";
    disturbance: [f64; 3] => "vec3", "true attitude disturbance D_iA, rad/s^2";
});

message!(ReferenceMsg, "formation.Reference", "Virtual leader, ground target and formation offsets at step k (undelayed).", {
    step: u64 => "integer", "simulation step k";
    t: f64 => "number", "simulation time t_k, s";
    target: [f64; 3] => "vec3", "ground target T_g, m";
    p_d: [f64; 3] => "vec3", "virtual leader P_d, m";
    offset: Vec<[f64; 3]> => "vec3_list", "formation offsets Delta_i0 of agents 1..N, m";
    desired: Vec<[f64; 3]> => "vec3_list", "desired positions P_d + Delta_i0 of agents 1..N, m";
});

/// Schema of `/events`: an injection accepted by the run, at the step it applies. The fields
/// after `agent` depend on `kind`.
pub fn event_schema() -> Value {
    let mut properties = serde_json::Map::new();
    for (name, kind, doc) in [
        ("step", "integer", "first step the injection applies to"),
        ("t", "number", "time of that step, s"),
        (
            "kind",
            "string",
            "`fault` (actuator fault) or `delay` (delay profile)",
        ),
        ("agent", "integer", "agent id, 1-based"),
        (
            "requested_step",
            "integer",
            "the step `--at` asked for (absent: as soon as possible)",
        ),
        (
            "gamma",
            "vec3",
            "fault: multiplicative fault Gamma_i from this step on",
        ),
        (
            "delta",
            "vec3",
            "fault: additive fault delta_i from this step on, N m",
        ),
        (
            "base_s",
            "number",
            "delay: tau_i(t) = base + amplitude sin(rate t): base, s",
        ),
        ("amplitude_s", "number", "delay: amplitude, s"),
        ("angular_rate_rad_s", "number", "delay: angular rate, rad/s"),
    ] {
        properties.insert(name.to_string(), field_schema(kind, doc));
    }
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": EVENT_SCHEMA_NAME,
        "description": "An injection accepted by the run (formation inject), at the step it applies.",
        "type": "object",
        "properties": properties,
        "required": ["step", "t", "kind", "agent"],
    })
}

/// Name of the schema of `/events`.
pub const EVENT_SCHEMA_NAME: &str = "formation.Event";

/// The channel ids of one agent.
struct AgentChannels {
    state: u16,
    command: u16,
    telemetry: u16,
    truth: u16,
}

/// A channel id and the number of messages written to it (the MCAP sequence number).
struct Sequence(BTreeMap<u16, u32>);

impl Sequence {
    fn next(&mut self, channel: u16) -> u32 {
        let n = self.0.entry(channel).or_insert(0);
        let s = *n;
        *n = n.wrapping_add(1);
        s
    }
}

/// Writer of `run.mcap` (runs on the recorder's writer thread, off the simulation loop).
pub struct McapSink {
    writer: mcap::Writer<BufWriter<File>>,
    agents: Vec<AgentChannels>,
    reference: u16,
    events: u16,
    dt_ns: u64,
    sequence: Sequence,
    buf: Vec<u8>,
    /// The 3D scene channels (`/tf`, `/scene/*`, `/log`, `/agent/{i}/plot`).
    #[cfg(feature = "foxglove")]
    scene: Option<super::mcap_scene::McapScene>,
}

fn mcap_error(e: mcap::McapError) -> std::io::Error {
    match e {
        mcap::McapError::Io(e) => e,
        e => std::io::Error::other(format!("run.mcap: {e}")),
    }
}

impl McapSink {
    /// Creates the file, its schemas and channels, the run's metadata and the scenario as an
    /// attachment (`scenario.toml`).
    pub fn create(path: &Path, s: &Scenario, variant: Variant) -> std::io::Result<McapSink> {
        let file = BufWriter::with_capacity(
            1 << 20,
            formation_config::node::files::create_replacing(path)?,
        );
        let mut writer = mcap::WriteOptions::new()
            .compression(None)
            .profile("")
            .create(file)
            .map_err(mcap_error)?;
        let mut schema = |name: &str, schema: Value| {
            writer.add_schema(name, SCHEMA_ENCODING, schema.to_string().as_bytes())
        };
        let ids = [
            schema(StateMsg::SCHEMA_NAME, StateMsg::schema()),
            schema(CommandMsg::SCHEMA_NAME, CommandMsg::schema()),
            schema(TelemetryMsg::SCHEMA_NAME, TelemetryMsg::schema()),
            schema(TruthMsg::SCHEMA_NAME, TruthMsg::schema()),
            schema(ReferenceMsg::SCHEMA_NAME, ReferenceMsg::schema()),
            schema(EVENT_SCHEMA_NAME, event_schema()),
        ];
        let mut schema_ids = [0u16; 6];
        for (slot, id) in schema_ids.iter_mut().zip(ids) {
            *slot = id.map_err(mcap_error)?;
        }
        let [state, command, telemetry, truth, reference, event] = schema_ids;
        let none = BTreeMap::new();
        let mut channel = |schema: u16, topic: String| {
            writer
                .add_channel(schema, &topic, MESSAGE_ENCODING, &none)
                .map_err(mcap_error)
        };
        let reference = channel(reference, "/reference".into())?;
        let events = channel(event, "/events".into())?;
        let mut agents = Vec::with_capacity(s.n_agents());
        for id in 1..=s.n_agents() {
            agents.push(AgentChannels {
                state: channel(state, format!("/agent/{id}/state"))?,
                command: channel(command, format!("/agent/{id}/command"))?,
                telemetry: channel(telemetry, format!("/agent/{id}/telemetry"))?,
                truth: channel(truth, format!("/agent/{id}/truth"))?,
            });
        }
        #[cfg(feature = "foxglove")]
        let scene = Some(super::mcap_scene::McapScene::create(&mut writer, s).map_err(mcap_error)?);
        let metadata = BTreeMap::from([
            ("scenario".to_string(), s.name.clone()),
            ("variant".to_string(), variant.name().to_string()),
            ("n_agents".to_string(), s.n_agents().to_string()),
            ("dt_s".to_string(), s.simulation.dt_s.to_string()),
            (
                "output_rate_hz".to_string(),
                s.simulation.output_rate_hz.to_string(),
            ),
        ]);
        writer
            .write_metadata(&mcap::records::Metadata {
                name: "formation".into(),
                metadata,
            })
            .map_err(mcap_error)?;
        writer
            .attach(&mcap::Attachment {
                log_time: 0,
                create_time: 0,
                name: "scenario.toml".into(),
                media_type: "application/toml".into(),
                data: Cow::Owned(s.to_toml_string().into_bytes()),
            })
            .map_err(mcap_error)?;
        Ok(McapSink {
            writer,
            agents,
            reference,
            events,
            dt_ns: (s.simulation.dt_s * 1e9).round() as u64,
            sequence: Sequence(BTreeMap::new()),
            buf: Vec::with_capacity(4096),
            #[cfg(feature = "foxglove")]
            scene,
        })
    }

    /// Writes `msg` to `channel` at step `step`.
    fn write<T: Serialize>(&mut self, channel: u16, step: u64, msg: &T) -> std::io::Result<()> {
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        serde_json::to_writer(&mut buf, msg)?;
        let result = self.write_bytes(channel, step * self.dt_ns, &buf);
        self.buf = buf;
        result
    }

    /// Writes an encoded message to `channel` at log time `time_ns`.
    fn write_bytes(&mut self, channel: u16, time_ns: u64, data: &[u8]) -> std::io::Result<()> {
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: self.sequence.next(channel),
            log_time: time_ns,
            publish_time: time_ns,
        };
        self.writer
            .write_to_known_channel(&header, data)
            .map_err(mcap_error)
    }

    /// Writes the messages of one output step: the reference, then per agent state, command,
    /// telemetry and truth.
    pub(crate) fn write_step(&mut self, rows: &Step<'_>) -> std::io::Result<()> {
        let Some(first) = rows.truths.first() else {
            return Ok(());
        };
        let (step, t) = (first.state.step, first.state.t);
        let p_d = rows.p_d();
        let desired = rows
            .offsets()
            .iter()
            .map(|o| [p_d[0] + o[0], p_d[1] + o[1], p_d[2] + o[2]])
            .collect();
        let reference = ReferenceMsg {
            step,
            t,
            target: rows.target(),
            p_d,
            offset: rows.offsets().to_vec(),
            desired,
        };
        self.write(self.reference, step, &reference)?;
        for (i, (truth, cmd)) in rows.truths.iter().zip(rows.commands).enumerate() {
            let ch = &self.agents[i];
            let (state, command, telemetry, truth_ch) =
                (ch.state, ch.command, ch.telemetry, ch.truth);
            let agent = i as u32 + 1;
            let [st, co, te, tr] = messages(agent, truth, cmd, rows.errors[i]);
            self.write(state, step, &st)?;
            self.write(command, step, &co)?;
            self.write(telemetry, step, &te)?;
            self.write(truth_ch, step, &tr)?;
        }
        #[cfg(feature = "foxglove")]
        if let Some(mut scene) = self.scene.take() {
            let result = scene.step(rows, |ch, time, data| self.write_bytes(ch, time, data));
            self.scene = Some(scene);
            result?;
        }
        Ok(())
    }

    /// An accepted injection (a line of `events.jsonl`): its event joins the scene's timeline
    /// (the scene channels mark it at its step).
    #[cfg_attr(not(feature = "foxglove"), allow(unused_variables))]
    pub(crate) fn injection(&mut self, line: &Value) {
        #[cfg(feature = "foxglove")]
        if let Some(scene) = &mut self.scene {
            scene.injection(line);
        }
    }

    /// Writes one `/events` message at step `step`.
    pub fn write_event(&mut self, step: u64, event: &Value) -> std::io::Result<()> {
        self.write(self.events, step, event)
    }

    /// Writes the summary section and closes the file.
    pub fn finish(mut self) -> std::io::Result<()> {
        self.writer.finish().map_err(mcap_error)?;
        use std::io::Write;
        self.writer.into_inner().flush()
    }
}

impl Sink for McapSink {
    fn cadence(&self) -> Cadence {
        Cadence::Output
    }

    fn step(&mut self, rows: &Step<'_>) -> std::io::Result<()> {
        self.write_step(rows)
    }

    /// The scene marks the injection; an accepted one is an `/events` message at its step.
    fn event(&mut self, line: &Value) -> std::io::Result<()> {
        self.injection(line);
        match event_message(line) {
            Some((step, event)) => self.write_event(step, &event),
            None => Ok(()),
        }
    }

    fn finish(self: Box<Self>) -> std::io::Result<()> {
        McapSink::finish(*self)
    }
}

/// The four per-agent messages of one step.
enum AgentMsg {
    State(StateMsg),
    Command(CommandMsg),
    Telemetry(Box<TelemetryMsg>),
    Truth(TruthMsg),
}

impl Serialize for AgentMsg {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            AgentMsg::State(m) => m.serialize(s),
            AgentMsg::Command(m) => m.serialize(s),
            AgentMsg::Telemetry(m) => m.serialize(s),
            AgentMsg::Truth(m) => m.serialize(s),
        }
    }
}

/// State, command, telemetry and truth of agent `agent` (1-based) at one step.
fn messages(agent: u32, truth: &PlantTruth, cmd: &ControlCommand, error_m: f64) -> [AgentMsg; 4] {
    let st = &truth.state;
    let tm = &cmd.telemetry;
    let (step, t) = (st.step, st.t);
    [
        AgentMsg::State(StateMsg {
            step,
            t,
            agent,
            position: st.position,
            velocity: st.velocity,
            attitude: st.attitude,
            rate: st.rate,
        }),
        AgentMsg::Command(CommandMsg {
            step,
            t,
            agent,
            thrust_n: cmd.thrust_n,
            torque_nm: cmd.torque_nm,
        }),
        AgentMsg::Telemetry(Box::new(TelemetryMsg {
            step,
            t,
            agent,
            formation_error_m: error_m,
            tau_s: tm.tau_s,
            e_p: tm.e_p,
            e_v: tm.e_v,
            u_p: tm.u_p,
            f_hat: tm.f_hat,
            nn_weight_norm: tm.nn_weight_norm,
            attitude_cmd_raw: tm.attitude_cmd_raw,
            attitude_cmd: tm.attitude_cmd,
            alpha: tm.alpha,
            z1: tm.z1,
            z2: tm.z2,
            blf1: tm.blf1,
            blf2: tm.blf2,
            c1: tm.c1,
            c2: tm.c2,
            gamma_hat: tm.gamma_hat,
            delta_hat: tm.delta_hat,
            d_hat: tm.d_hat,
            model_hat_dev: tm.model_hat_dev,
            e1: tm.e1,
            e2: tm.e2,
        })),
        AgentMsg::Truth(TruthMsg {
            step,
            t,
            agent,
            thrust_n: truth.thrust_n,
            torque_applied_nm: truth.torque_applied_nm,
            gamma: truth.gamma,
            delta: truth.delta,
            uncertainty: truth.uncertainty,
            disturbance: truth.disturbance,
        }),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys(v: &Value) -> Vec<String> {
        let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
        k.sort();
        k
    }

    #[test]
    fn every_message_has_exactly_the_fields_its_schema_declares() {
        let truth = PlantTruth::default();
        let cmd = ControlCommand::default();
        let schemas = [
            StateMsg::schema(),
            CommandMsg::schema(),
            TelemetryMsg::schema(),
            TruthMsg::schema(),
        ];
        for (msg, schema) in messages(1, &truth, &cmd, 0.0).iter().zip(&schemas) {
            let v = serde_json::to_value(msg).unwrap();
            assert_eq!(keys(&v), keys(&schema["properties"]), "{}", schema["title"]);
            let required: Vec<&str> = schema["required"]
                .as_array()
                .unwrap()
                .iter()
                .map(|r| r.as_str().unwrap())
                .collect();
            assert_eq!(required.len(), keys(&v).len());
        }
        let reference = ReferenceMsg {
            step: 0,
            t: 0.0,
            target: [0.0; 3],
            p_d: [0.0; 3],
            offset: vec![],
            desired: vec![],
        };
        assert_eq!(
            keys(&serde_json::to_value(&reference).unwrap()),
            keys(&ReferenceMsg::schema()["properties"])
        );
    }

    #[test]
    fn an_injection_becomes_an_event_without_wall_time_or_nonce_and_a_rejection_none() {
        let line = json!({
            "wall_time_unix_s": 1.5, "event": "fault", "nonce": 7, "agent": 2, "step": 3937,
            "t": 3.937, "requested_step": null, "recorded_step": 3800, "after_end": false,
            "gamma": [0.5, 0.5, 0.5], "delta": [0.0, 0.0, 0.0],
        });
        let (step, e) = event_message(&line).expect("an accepted fault");
        assert_eq!(step, 3937);
        assert_eq!(
            e,
            json!({"step": 3937, "t": 3.937, "kind": "fault", "agent": 2,
                   "gamma": [0.5, 0.5, 0.5], "delta": [0.0, 0.0, 0.0]})
        );
        let schema = event_schema();
        for k in keys(&e) {
            assert!(
                schema["properties"].get(&k).is_some(),
                "{k} not in the schema"
            );
        }
        assert!(event_message(&json!({"event": "rejected", "nonce": 1})).is_none());
    }
}
