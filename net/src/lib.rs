//! Multi-host runs over Eclipse Zenoh: one formation across several machines.
//!
//! * [`auth`]: each run's secret and the proof of it every request, reply, frame and report
//!   carries.
//! * [`logs`]: log lines about what arrives from the network, at most one a second per source and
//!   reason.
//! * [`session`]: Zenoh sessions of this project (topology, endpoints: an owner-only Unix socket
//!   by default, TCP with user/password, mutual TLS; a bounded number of runtime threads).
//! * [`tls`]: the CA and per-host certificates of `tls/` endpoints (`formation certs`), and the
//!   pre-flight handshake that names a peer refused.
//! * [`proto`]: the keys and messages between an orchestrator and the host daemons.
//! * [`identity`]: protocol version, build identity and wire-layout hash, compared at the handshake.
//! * [`plan`]: which services cross hosts for a placement, and in which direction.
//! * [`colocate`]: a host whose daemon shares the launcher's `/dev/shm` and user: its agents use
//!   the launcher's services, and nothing is bridged for it.
//! * [`bridge`]: the per-host bridge forwarding exactly those services, as the same `#[repr(C)]`
//!   bytes with their wire type name.
//! * [`priority`]: in a realtime run, the bridge's and Zenoh's link threads under `SCHED_FIFO`
//!   at the run's priority, like the plant and the agents they carry messages between.
//! * [`clock`]: the hosts' clock offsets and the one-way delay of every cross-host link.
//! * [`bench`]: bare Zenoh links and the frames of a split lockstep step, for `formation bench`.
//! * [`daemon`]: `formation host`, which spawns a run's role processes on its machine.
//! * [`cluster`]: the orchestrator's side: listing hosts, the handshake, remote processes.
//! * [`export`]: a run's telemetry for outside readers over Zenoh (`formation run --zenoh-listen`).
//! * [`probe`]: a plain client that puts and asks arbitrary bytes on arbitrary keys (the attacks of
//!   the end-to-end tests).
//! * [`survey`]: `formation hosts`, every daemon reachable through any of the given endpoints.
//!
//! The topology (docs/multi-host.md): every host daemon is a Zenoh *router* that listens (on an
//! owner-only Unix socket unless given authenticated or TLS endpoints); the launching orchestrator opens a Zenoh *router* session that
//! connects to each daemon, so traffic between two remote hosts is routed through the launching
//! machine (a router does not relay between the peers of its region, and Zenoh >= 1.9 peers do not
//! relay for each other, so the daemons are routers, not peers). Multicast scouting is off
//! everywhere.
#![warn(missing_docs)]

pub mod auth;
pub mod bench;
pub mod bridge;
pub mod clock;
pub mod cluster;
pub mod colocate;
pub mod daemon;
pub mod export;
pub mod identity;
pub mod logs;
pub mod plan;
pub mod priority;
pub mod probe;
pub mod proto;
pub mod session;
pub mod survey;
pub mod tls;
