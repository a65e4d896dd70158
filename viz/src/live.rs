//! The live view: a Foxglove WebSocket server (Foxglove SDK) fed with the scene of a running run.
//!
//! The run's recorder hands a [`Frame`] to [`LiveView::offer`] at every scene frame; the frame
//! goes through a bounded queue ([`FRAME_QUEUE`]) to the viewer thread, which builds and encodes
//! the scene and logs it to the server's channels. `offer` never blocks: when the queue is full
//! (a slow viewer thread) the frame is dropped and counted. The server itself keeps a bounded
//! backlog per client and drops the oldest messages of a client that does not keep up, so
//! neither a slow nor a vanished viewer stalls the run.
//!
//! Rate: every scene frame (25 Hz of simulation time) updates the trails; at most
//! [`MAX_PUBLISH_HZ`] scene frames per second of wall time are sent to the viewers (a lockstep
//! run at 15x real time shows every ~15th frame), and the last frame of the run always is. With
//! no viewer connected nothing is built or encoded.

use crate::channels::{channels, encode, Encoded};
use crate::frame::Frame;
use crate::scene::{step_ns, SceneBuilder, SceneConfig};
use formation_config::scenario::events::Event;
use foxglove::websocket::Capability;
use foxglove::{Context, PartialMetadata, RawChannel, WebSocketServer, WebSocketServerHandle};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Default address of `--foxglove` (Foxglove's default port).
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";
/// Frames the queue between the recorder and the viewer thread holds (1.6 s of simulation at
/// 25 Hz); a frame offered to a full queue is dropped.
pub const FRAME_QUEUE: usize = 40;
/// Most scene frames sent to the viewers per second of wall time.
pub const MAX_PUBLISH_HZ: f64 = 30.0;
/// Messages the server queues per client before it drops the oldest (the SDK's default is 1024).
pub const CLIENT_BACKLOG: usize = 1024;
/// Nice value of the viewer thread and the server's thread: below the run's processes.
const VIEWER_NICE: i32 = 10;

/// Why the live view could not start.
#[derive(Debug)]
pub enum LiveError {
    /// `--foxglove ADDR` is not `HOST:PORT`.
    Address(String),
    /// The server's runtime could not be created.
    Runtime(std::io::Error),
    /// The server could not bind or start.
    Server(String),
}

impl std::fmt::Display for LiveError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LiveError::Address(a) => write!(
                f,
                "--foxglove {a}: expected HOST:PORT (e.g. {DEFAULT_ADDR}; port 0 picks a free one)"
            ),
            LiveError::Runtime(e) => write!(f, "Foxglove server: cannot start its runtime: {e}"),
            LiveError::Server(e) => write!(f, "Foxglove server: {e}"),
        }
    }
}

impl std::error::Error for LiveError {}

/// What the live view did, for the run's log.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LiveStats {
    /// Scene frames offered by the run.
    pub offered: u64,
    /// Frames dropped because the viewer thread was behind.
    pub dropped: u64,
    /// Frames sent to at least one viewer.
    pub published: u64,
}

enum Msg {
    Frame(Box<Frame>),
    Event(Box<Event>),
}

/// A running live view (server and viewer thread); [`LiveView::finish`] stops both.
pub struct LiveView {
    tx: Option<SyncSender<Msg>>,
    /// Events go through their own unbounded queue: they are rare and none may be lost.
    events: Option<mpsc::Sender<Msg>>,
    thread: Option<JoinHandle<u64>>,
    addr: SocketAddr,
    decimation: u64,
    offered: u64,
    dropped: Arc<AtomicU64>,
    viewers: Arc<Viewers>,
}

/// Counts the connected viewers (the server's listener).
#[derive(Default)]
struct Viewers(AtomicUsize);

impl foxglove::websocket::ServerListener for Viewers {
    fn on_client_connect(&self) {
        self.0.fetch_add(1, Ordering::SeqCst);
    }

    fn on_client_disconnect(&self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Splits `HOST:PORT` (an IPv6 host in brackets).
pub fn parse_addr(addr: &str) -> Result<(String, u16), LiveError> {
    let bad = || LiveError::Address(addr.to_string());
    let (host, port) = addr.rsplit_once(':').ok_or_else(bad)?;
    let host = host.trim_start_matches('[').trim_end_matches(']');
    if host.is_empty() {
        return Err(bad());
    }
    Ok((host.to_string(), port.parse().map_err(|_| bad())?))
}

fn lower_priority() {
    // SAFETY: setpriority on the calling thread (who = 0) with a valid nice value; a failure
    // only leaves the priority as it was.
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, VIEWER_NICE);
    }
}

impl LiveView {
    /// Starts the server on `addr` (`HOST:PORT`; port 0 picks a free one) for a run of `cfg`
    /// with the scenario's `events`, named `name` in the viewer.
    pub fn start(
        addr: &str,
        name: &str,
        cfg: SceneConfig,
        events: &[Event],
    ) -> Result<LiveView, LiveError> {
        let (host, port) = parse_addr(addr)?;
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("fm-foxglove")
            .on_thread_start(lower_priority)
            .enable_all()
            .build()
            .map_err(LiveError::Runtime)?;
        let ctx = Context::new();
        let viewers = Arc::new(Viewers::default());
        let server = WebSocketServer::new()
            .listener(viewers.clone())
            .name(name)
            .bind(host.clone(), port)
            .context(&ctx)
            .capabilities([Capability::Time])
            .message_backlog_size(CLIENT_BACKLOG)
            .tokio_runtime(runtime.handle())
            .start_blocking()
            .map_err(|e| LiveError::Server(format!("cannot serve on {addr}: {e}")))?;
        let ip = host
            .parse()
            .unwrap_or(std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST));
        let bound = SocketAddr::new(ip, server.port());
        let specs = channels(cfg.n);
        let mut raw = Vec::with_capacity(specs.len());
        for s in specs {
            let ch = ctx
                .channel_builder(s.topic.clone())
                .message_encoding(s.message_encoding)
                .schema(foxglove::Schema::from(s.schema))
                .build_raw()
                .map_err(|e| LiveError::Server(format!("channel {}: {e}", s.topic)))?;
            raw.push(ch);
        }
        let decimation = cfg.decimation;
        let builder = SceneBuilder::new(cfg, events);
        let (tx, rx) = mpsc::sync_channel(FRAME_QUEUE);
        let (etx, erx) = mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("fm-viewer".into())
            .spawn(move || {
                lower_priority();
                let published = Viewer {
                    _context: ctx,
                    builder,
                    channels: raw,
                    server,
                    encoded: Vec::new(),
                }
                .run(rx, erx);
                drop(runtime);
                published
            })
            .map_err(LiveError::Runtime)?;
        Ok(LiveView {
            tx: Some(tx),
            events: Some(etx),
            thread: Some(thread),
            addr: bound,
            decimation,
            offered: 0,
            dropped: Arc::new(AtomicU64::new(0)),
            viewers,
        })
    }

    /// Number of viewers connected now.
    pub fn viewers(&self) -> usize {
        self.viewers.0.load(Ordering::SeqCst)
    }

    /// Waits until a viewer is connected or `timeout` passes (before a run starts: a lockstep
    /// run of a few seconds would end before anyone could join); whether one is connected.
    pub fn wait_for_viewer(&self, timeout: Duration) -> bool {
        let start = Instant::now();
        while self.viewers() == 0 {
            if start.elapsed() >= timeout {
                return false;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        true
    }

    /// The address the server listens on (the bound port when 0 was asked for).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Whether step k is a scene frame (the recorder builds a [`Frame`] only for those).
    pub fn wants(&self, k: u64) -> bool {
        k.is_multiple_of(self.decimation)
    }

    /// Hands a scene frame to the viewer thread; never blocks (a full queue drops it).
    pub fn offer(&mut self, frame: Frame) {
        self.offered += 1;
        if let Some(tx) = &self.tx {
            if let Err(TrySendError::Full(_)) = tx.try_send(Msg::Frame(Box::new(frame))) {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// An event injected into the run (before its step is recorded).
    pub fn event(&mut self, e: Event) {
        if let Some(tx) = &self.events {
            let _ = tx.send(Msg::Event(Box::new(e)));
        }
    }

    /// Publishes what is queued, stops the server and the thread.
    pub fn finish(mut self) -> LiveStats {
        self.stop()
    }

    fn stop(&mut self) -> LiveStats {
        self.tx.take();
        self.events.take();
        let published = self.thread.take().and_then(|t| t.join().ok()).unwrap_or(0);
        LiveStats {
            offered: self.offered,
            dropped: self.dropped.load(Ordering::Relaxed),
            published,
        }
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        self.stop();
    }
}

/// The viewer thread's state.
struct Viewer {
    /// The channels' context: channels and server sinks hold it weakly, it lives as long as the
    /// viewer.
    _context: Arc<Context>,
    builder: SceneBuilder,
    channels: Vec<Arc<RawChannel>>,
    server: WebSocketServerHandle,
    encoded: Vec<Encoded>,
}

impl Viewer {
    fn run(mut self, frames: Receiver<Msg>, events: Receiver<Msg>) -> u64 {
        let min_gap = Duration::from_secs_f64(1.0 / MAX_PUBLISH_HZ);
        let mut last_publish: Option<Instant> = None;
        let mut pending: Option<Box<Frame>> = None;
        let mut published = 0;
        while let Ok(msg) = frames.recv() {
            while let Ok(Msg::Event(e)) = events.try_recv() {
                self.builder.add_event(&e);
            }
            let Msg::Frame(f) = msg else { continue };
            let due = last_publish.is_none_or(|t| t.elapsed() >= min_gap);
            if due && self.server.client_count() > 0 {
                self.publish(&f);
                published += 1;
                last_publish = Some(Instant::now());
                pending = None;
            } else {
                self.builder.push(&f);
                pending = Some(f);
            }
        }
        // The run is over: its last frame is shown.
        if let Some(f) = pending {
            if self.server.client_count() > 0 {
                let scene = self.builder.emit(&f);
                self.send(&scene, f.step);
                published += 1;
            }
        }
        self.server.stop().wait_blocking();
        published
    }

    fn publish(&mut self, f: &Frame) {
        let scene = self.builder.build(f);
        self.send(&scene, f.step);
    }

    fn send(&mut self, scene: &crate::scene::Scene, step: u64) {
        let dt = self.builder.config().dt;
        self.encoded.clear();
        encode(scene, dt, &mut self.encoded);
        for m in &self.encoded {
            self.channels[m.channel].log_with_meta(
                &m.data,
                PartialMetadata {
                    log_time: Some(m.log_time_ns),
                },
            );
        }
        self.server.broadcast_time(step_ns(step, dt));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_address_is_host_and_port_and_a_bad_one_is_named() {
        assert_eq!(
            parse_addr("127.0.0.1:8765").unwrap(),
            ("127.0.0.1".into(), 8765)
        );
        assert_eq!(parse_addr("[::1]:0").unwrap(), ("::1".into(), 0));
        let e = parse_addr("localhost").unwrap_err().to_string();
        assert!(
            e.contains("--foxglove localhost") && e.contains("HOST:PORT"),
            "{e}"
        );
        assert!(parse_addr(":80").is_err());
        assert!(parse_addr("host:99999").is_err());
    }
}
