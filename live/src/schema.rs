//! `formation schema [--json | --markdown] [--n N]`: every service of a run, read from the typed
//! service table (`formation_config::protocol::services`) — name pattern, scope, message type
//! (Rust and iceoryx2 names, size, alignment), who sends and receives, history, and the limits the
//! orchestrator creates it with for N agents — and the per-field layout of every wire type (name,
//! offset, size, type, unit; `formation_config::protocol::layout`). `docs/services.md` is its
//! `--markdown` output.

use crate::error::LiveError;
use formation_config::protocol::layout::{every_type, TypeLayout};
use formation_config::protocol::services::{
    self, wire_type_name, Event, Limits, Message, Named, Party, Scope, Sizing, Slice, Topic,
    Visitor,
};
use serde::Serialize;
use std::convert::Infallible;

/// Arguments of `formation schema`.
#[derive(clap::Args, Debug)]
pub struct SchemaArgs {
    /// Number of agents the limits are sized for (1..=128).
    #[arg(long, default_value_t = 5, value_parser = formation_runtime::cli::whole_number::<usize>)]
    pub n: usize,
    /// Print `{"n", "services": [{"pattern", "scope", "kind", "message", ...}]}`.
    #[arg(long, conflicts_with = "markdown")]
    pub json: bool,
    /// Print the Markdown page kept as docs/services.md.
    #[arg(long)]
    pub markdown: bool,
}

/// The message a publish-subscribe service carries.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct MessageType {
    /// Rust type, without its module path (`[T]` for a slice of one `T` per agent).
    pub rust: String,
    /// iceoryx2 type name (`#[type_name]`), what an outside client must declare.
    pub iceoryx2: &'static str,
    /// Whether a sample is a slice of N elements rather than one value.
    pub slice: bool,
    /// Size of one element in bytes.
    pub size: usize,
    /// Alignment in bytes.
    pub align: usize,
}

/// Upper bounds the service is created with (see `services::Limits`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct ServiceLimits {
    /// Nodes that may open it.
    pub nodes: usize,
    /// Publishers or notifiers.
    pub senders: usize,
    /// Subscribers or listeners.
    pub receivers: usize,
    /// Samples a subscriber buffers (publish-subscribe only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub buffer: Option<usize>,
}

/// One service of the table.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Service {
    /// Name pattern relative to the run prefix (`{i}`: 0-based agent index).
    pub pattern: &'static str,
    /// `run` or `per agent`.
    pub scope: &'static str,
    /// `publish-subscribe` or `event`.
    pub kind: &'static str,
    /// The message (publish-subscribe only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub message: Option<MessageType>,
    /// Publishers or notifiers.
    pub senders: Vec<&'static str>,
    /// Subscribers or listeners.
    pub receivers: Vec<&'static str>,
    /// Samples kept for late subscribers (publish-subscribe only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub history: Option<usize>,
    /// Limits for the requested N.
    pub limits: ServiceLimits,
    /// What it carries or wakes.
    pub doc: &'static str,
}

/// One field of a wire type.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct FieldRow {
    /// Field name.
    pub name: &'static str,
    /// Byte offset from the start of the type.
    pub offset: usize,
    /// Size in bytes.
    pub size: usize,
    /// Rust type (`u32`, `u64`, `f64`, `[f64; 3]`, `[[f64; 3]; 128]` or another wire type).
    #[serde(rename = "type")]
    pub ty: &'static str,
    /// Unit, `-` for none.
    pub unit: &'static str,
}

/// The layout of one wire type.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct WireType {
    /// Rust name.
    pub name: &'static str,
    /// iceoryx2 type name, for the types a service carries.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iceoryx2: Option<&'static str>,
    /// Size in bytes.
    pub size: usize,
    /// Alignment in bytes.
    pub align: usize,
    /// Fields in offset order.
    pub fields: Vec<FieldRow>,
}

/// The services of a run of `n` agents, in the order the orchestrator creates them (run-wide ones
/// first, then each per-agent service once, by its pattern), and the wire types they carry.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Schema {
    /// Number of agents the limits are sized for.
    pub n: usize,
    /// Outside observers the limits make room for (`formation run --observers`, default).
    pub observers: usize,
    /// The services.
    pub services: Vec<Service>,
    /// Every wire type, each after the types nested in it.
    pub types: Vec<WireType>,
}

fn wire_type(t: &TypeLayout, services: &[Service]) -> WireType {
    WireType {
        name: t.name,
        iceoryx2: services
            .iter()
            .filter_map(|s| s.message.as_ref())
            .find(|m| m.rust.trim_matches(['[', ']']) == t.name)
            .map(|m| m.iceoryx2),
        size: t.size,
        align: t.align,
        fields: t
            .fields
            .iter()
            .map(|f| FieldRow {
                name: f.name,
                offset: f.offset,
                size: f.size,
                ty: f.ty,
                unit: f.unit,
            })
            .collect(),
    }
}

fn scope_name(s: Scope) -> &'static str {
    match s {
        Scope::Run => "run",
        Scope::PerAgent => "per agent",
    }
}

fn parties(p: &[Party]) -> Vec<&'static str> {
    p.iter().map(|p| p.name()).collect()
}

fn short_rust_name<T>() -> &'static str {
    let full = core::any::type_name::<T>();
    full.rsplit("::").next().unwrap_or(full)
}

fn limits(l: Limits, buffer: bool) -> ServiceLimits {
    ServiceLimits {
        nodes: l.nodes,
        senders: l.senders,
        receivers: l.receivers,
        buffer: buffer.then_some(l.buffer),
    }
}

/// Collects each service once (by pattern) while `services::visit` walks a run.
struct Collect(Vec<Service>);

impl Collect {
    fn push_topic<T: Message, S>(&mut self, t: &Topic<T, S>, l: Limits, slice: bool) {
        if self.0.iter().any(|s| s.pattern == t.pattern) {
            return;
        }
        let (size, align) = t.layout();
        let rust = short_rust_name::<T>();
        self.0.push(Service {
            pattern: t.pattern,
            scope: scope_name(t.scope),
            kind: "publish-subscribe",
            message: Some(MessageType {
                rust: if slice {
                    format!("[{rust}]")
                } else {
                    rust.to_string()
                },
                iceoryx2: wire_type_name::<T>(),
                slice,
                size,
                align,
            }),
            senders: parties(t.publishers),
            receivers: parties(t.subscribers),
            history: Some(t.history),
            limits: limits(l, true),
            doc: t.doc,
        });
    }
}

impl Visitor for Collect {
    type Error = Infallible;
    fn topic<T: Message>(&mut self, s: Named<Topic<T>>, l: Limits) -> Result<(), Infallible> {
        self.push_topic(s.spec, l, false);
        Ok(())
    }
    fn slices<T: Message>(
        &mut self,
        s: Named<Topic<T, Slice>>,
        l: Limits,
    ) -> Result<(), Infallible> {
        self.push_topic(s.spec, l, true);
        Ok(())
    }
    fn event(&mut self, s: Named<Event>, l: Limits) -> Result<(), Infallible> {
        let e: &Event = s.spec;
        if !self.0.iter().any(|x| x.pattern == e.pattern) {
            self.0.push(Service {
                pattern: e.pattern,
                scope: scope_name(e.scope),
                kind: "event",
                message: None,
                senders: parties(e.notifiers),
                receivers: parties(e.listeners),
                history: None,
                limits: limits(l, false),
                doc: e.doc,
            });
        }
        Ok(())
    }
}

/// Largest degree of the graph [`schema`] sizes the neighbour shares for: a path, the paper's
/// graph and `formation scenario`'s default.
const SCHEMA_GRAPH_DEGREE: usize = 2;

/// The schema of a lockstep run of `n >= 1` agents on a path graph with the default numbers of
/// clients and observers (a run sizes the neighbour shares by its own graph's largest degree).
pub fn schema(n: usize) -> Schema {
    let mut c = Collect(Vec::new());
    let sizing =
        Sizing::run(n, false).with_neighbours(SCHEMA_GRAPH_DEGREE.min(n.saturating_sub(1)));
    let Ok(()) = services::visit(&sizing, &mut c);
    let types = every_type().iter().map(|t| wire_type(t, &c.0)).collect();
    Schema {
        n,
        observers: sizing.observers,
        services: c.0,
        types,
    }
}

const FIELD_HEADER: [&str; 5] = ["field", "offset", "size", "type", "unit"];

fn field_cells(f: &FieldRow) -> Vec<String> {
    vec![
        f.name.to_string(),
        f.offset.to_string(),
        f.size.to_string(),
        f.ty.to_string(),
        f.unit.to_string(),
    ]
}

/// One line introducing a wire type: name, iceoryx2 name, size, alignment.
fn type_title(t: &WireType) -> String {
    let iox = t
        .iceoryx2
        .map_or_else(String::new, |n| format!(", iceoryx2 `{n}`"));
    format!("{}{iox}: {} bytes, align {}", t.name, t.size, t.align)
}

/// The cells of one row, in the order of [`HEADER`].
fn cells(s: &Service) -> Vec<String> {
    let opt = |v: Option<usize>| v.map_or_else(|| "-".to_string(), |v| v.to_string());
    let (rust, iox, size, align) = match &s.message {
        Some(m) => (
            m.rust.clone(),
            m.iceoryx2.to_string(),
            m.size.to_string(),
            m.align.to_string(),
        ),
        None => ("-".into(), "-".into(), "-".into(), "-".into()),
    };
    vec![
        s.pattern.to_string(),
        s.scope.to_string(),
        s.kind.to_string(),
        rust,
        iox,
        size,
        align,
        s.senders.join(", "),
        s.receivers.join(", "),
        opt(s.history),
        s.limits.nodes.to_string(),
        s.limits.senders.to_string(),
        s.limits.receivers.to_string(),
        opt(s.limits.buffer),
    ]
}

const HEADER: [&str; 14] = [
    "service",
    "scope",
    "kind",
    "message",
    "iceoryx2 type name",
    "size",
    "align",
    "senders",
    "receivers",
    "history",
    "max nodes",
    "max senders",
    "max receivers",
    "buffer",
];

/// Rows as plain text, columns padded to their widest cell.
fn padded(header: &[&str], body: impl Iterator<Item = Vec<String>>) -> String {
    let rows: Vec<Vec<String>> = std::iter::once(header.iter().map(|h| h.to_string()).collect())
        .chain(body)
        .collect();
    let widths: Vec<usize> = (0..header.len())
        .map(|c| rows.iter().map(|r| r[c].chars().count()).max().unwrap_or(0))
        .collect();
    let mut out = String::new();
    for r in &rows {
        let line: Vec<String> = r
            .iter()
            .zip(&widths)
            .map(|(cell, w)| format!("{cell:<w$}"))
            .collect();
        out.push_str(line.join("  ").trim_end());
        out.push('\n');
    }
    out
}

/// A plain-text table of the services, then each wire type's fields.
pub fn text(schema: &Schema) -> String {
    let mut out = format!(
        "services of a run of N = {} agents with room for {} observers (names relative to the run prefix fm<run id>_; {{i}}: 0-based agent index)\n",
        schema.n, schema.observers
    );
    out += &padded(&HEADER, schema.services.iter().map(cells));
    for t in &schema.types {
        out += &format!("\n{}\n", type_title(t).replace('`', ""));
        out += &padded(&FIELD_HEADER, t.fields.iter().map(field_cells));
    }
    out
}

/// The Markdown page kept as `docs/services.md`.
pub fn markdown(schema: &Schema) -> String {
    let mut out = String::from(
        "# Services of a run\n\n\
         Generated by `formation schema --markdown > docs/services.md` from the typed service table\n\
         (`config/src/protocol/services.rs`); a unit test fails when this page differs from it.\n\
         `formation schema --json` prints the same table for programs.\n\n\
         Names are relative to the run's iceoryx2 prefix `fm<run id>_`; `{i}` is the 0-based agent\n\
         index. A client opening a publish-subscribe service must declare its message with the\n\
         iceoryx2 type name and the same size and alignment (`#[repr(C)]`, fields in\n\
         `config/src/protocol/wire.rs` and `messages.rs`); a slice service carries N elements per\n\
         sample. Senders are publishers or notifiers, receivers subscribers or listeners. Limits are\n",
    );
    out.push_str(&format!(
        "those the orchestrator creates a lockstep run of N = {} agents on a path with (`formation schema\n\
         --n N` prints them for another N; a realtime run has a deeper `formation/plant/steps` buffer;\n\
         an agent's `share` has 2 d + 1 subscribers, d the largest degree of the run's graph: one per\n\
         neighbour, as many for neighbours taking over, one for a host bridge).\n\n\
         Every service has room for {} outside observers (`formation run --observers K`, default {}):\n\
         K receivers (subscribers or listeners) and K nodes more than the run and its clients\n\
         (`formation inspect`, `formation inject`) need, so a program the run does not know about can\n\
         watch any state, command, telemetry, step record, event or wake-up. An observer never slows\n\
         the run: publishers overwrite the oldest sample of a full subscriber buffer, and a listener\n\
         only receives wake-ups. To see the end of a run, subscribe to `formation/run/control`: the\n\
         orchestrator publishes `RunControl {{ kind: 1 }}` (stop) there when the run ends.\n\n",
        schema.n, schema.observers, services::DEFAULT_OBSERVERS
    ));
    out.push_str(&format!("| {} | what |\n", HEADER.join(" | ")));
    out.push_str(&format!("|{}\n", "---|".repeat(HEADER.len() + 1)));
    for s in &schema.services {
        let mut c = cells(s);
        c[0] = format!("`{}`", c[0]);
        if s.message.is_some() {
            c[4] = format!("`{}`", c[4]);
        }
        out.push_str(&format!("| {} | {} |\n", c.join(" | "), s.doc));
    }
    out.push_str(
        "\n## Wire layout\n\n\
         Each type is `#[repr(C)]`, little-endian, fields in this order at these byte offsets (a\n\
         `_pad` field is zero). A type in the type column is another wire type below, nested in\n\
         place. The tables are kept next to the structs (`wire_fields!`) and checked against\n\
         `offset_of!` by a unit test; `clients/python/formation_client` and\n\
         `clients/c/formation_wire.h` are checked against `formation schema --json` by tests.\n",
    );
    for t in &schema.types {
        out.push_str(&format!("\n### {}\n\n", type_title(t)));
        out.push_str(&format!("| {} |\n", FIELD_HEADER.join(" | ")));
        out.push_str(&format!("|{}\n", "---|".repeat(FIELD_HEADER.len())));
        for f in &t.fields {
            let mut c = field_cells(f);
            c[0] = format!("`{}`", c[0]);
            c[3] = format!("`{}`", c[3]);
            out.push_str(&format!("| {} |\n", c.join(" | ")));
        }
    }
    out
}

/// Entry point of `formation schema`.
pub fn main(args: SchemaArgs) -> Result<(), LiveError> {
    if !(1..=formation_config::MAX_AGENTS).contains(&args.n) {
        return Err(LiveError::AgentCount {
            n: args.n,
            max: formation_config::MAX_AGENTS,
        });
    }
    let s = schema(args.n);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
    } else if args.markdown {
        print!("{}", markdown(&s));
    } else {
        print!("{}", text(&s));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_config::protocol::wire::AgentTelemetry;

    #[test]
    fn docs_services_md_is_the_generated_markdown_of_a_five_agent_run() {
        let generated = markdown(&schema(5));
        assert!(
            generated == include_str!("../../docs/services.md"),
            "docs/services.md is stale: regenerate it with \
             `formation schema --markdown > docs/services.md`"
        );
    }

    #[test]
    fn the_schema_lists_each_service_of_the_table_once_with_its_wire_type_and_layout() {
        let s = schema(3);
        assert_eq!(s.services.len(), 12 + 5);
        let tel = s
            .services
            .iter()
            .find(|x| x.pattern == "formation/agent/{i}/telemetry")
            .expect("telemetry");
        let m = tel.message.as_ref().expect("a message");
        assert_eq!(m.rust, "AgentTelemetry");
        assert_eq!(m.iceoryx2, "formation.v2.AgentTelemetry");
        assert_eq!(
            (m.size, m.align),
            (
                size_of::<formation_config::protocol::wire::AgentTelemetry>(),
                align_of::<formation_config::protocol::wire::AgentTelemetry>()
            )
        );
        assert_eq!(tel.scope, "per agent");
        assert_eq!(tel.history, Some(1));
        assert_eq!(tel.receivers, vec!["clients"]);
        let steps = s
            .services
            .iter()
            .find(|x| x.pattern == "formation/plant/steps")
            .expect("steps");
        assert_eq!(steps.message.as_ref().map(|m| m.slice), Some(true));
        let wake = s
            .services
            .iter()
            .find(|x| x.pattern == "formation/wake/agent/{i}")
            .expect("wake");
        assert_eq!(wake.kind, "event");
        assert!(wake.message.is_none() && wake.limits.buffer.is_none());
    }

    #[test]
    fn limits_follow_the_requested_number_of_agents() {
        let share = |n: usize| {
            schema(n)
                .services
                .into_iter()
                .find(|x| x.pattern == "formation/agent/{i}/share")
                .expect("share")
                .limits
        };
        let k = services::DEFAULT_OBSERVERS;
        // On a path of 9 the share has two neighbours' slots, twice, and the bridge's; on a path
        // of 2 one neighbour's, twice, and the bridge's. Every service admits every node of the run.
        assert_eq!(share(9).receivers, 2 * 2 + 1 + k);
        assert_eq!(share(9).nodes, 9 + 4 + services::MAX_CLIENTS + k);
        assert_eq!(share(2).receivers, 2 + 1 + k);
    }

    #[test]
    fn the_json_names_every_field_a_client_needs() {
        let v = serde_json::to_value(schema(5)).expect("serialises");
        let first = &v["services"][0];
        for key in [
            "pattern",
            "scope",
            "kind",
            "message",
            "senders",
            "receivers",
            "history",
            "limits",
        ] {
            assert!(first.get(key).is_some(), "{key} in {first}");
        }
        assert_eq!(first["message"]["iceoryx2"], "formation.v1.ReferenceFrame");
        let tel = v["types"]
            .as_array()
            .expect("types")
            .iter()
            .find(|t| t["name"] == "AgentTelemetry")
            .expect("AgentTelemetry");
        assert_eq!(tel["iceoryx2"], "formation.v2.AgentTelemetry");
        assert_eq!(tel["size"], size_of::<AgentTelemetry>());
        let loop_latency = tel["fields"]
            .as_array()
            .expect("fields")
            .iter()
            .find(|f| f["name"] == "loop_latency_us")
            .expect("loop_latency_us");
        assert_eq!(
            loop_latency["offset"],
            core::mem::offset_of!(AgentTelemetry, loop_latency_us)
        );
        assert_eq!(loop_latency["type"], "f64");
        assert_eq!(loop_latency["unit"], "us");
    }

    #[test]
    fn text_and_markdown_list_each_wire_types_fields_with_offset_and_unit() {
        let s = schema(5);
        let t = text(&s);
        assert!(
            t.contains("AgentTelemetry, iceoryx2 formation.v2.AgentTelemetry: 528 bytes, align 8")
        );
        assert!(t.lines().any(|l| l.split_whitespace().collect::<Vec<_>>()
            == ["formation_error_m", "24", "8", "f64", "m"]));
        let m = markdown(&s);
        assert!(m.contains("| `formation_error_m` | 24 | 8 | `f64` | m |"));
    }
}
