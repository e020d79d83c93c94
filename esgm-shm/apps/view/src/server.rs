//! The server: a Foxglove WebSocket server whose channels are a domain's trajectories.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock, Weak};
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::Context as _;
use esgm_core::Esgm;
use esgm_core::esgm::TrajectoryKind;
use esgm_shm::ShmEsgm;
use foxglove::websocket::{Capability, ChannelView, Client, ServerListener};
use foxglove::{
    ChannelBuilder, ChannelId, Context, RawChannel, Schema, WebSocketServer, WebSocketServerHandle,
};
use parking_lot::Mutex;

use crate::door::Door;
use crate::encoding::Encoding;
use crate::forward::{Counters, Forwarder, Shown};
use crate::trace_view;

/// How often the trajectory listing is read for trajectories that came or went.
const DISCOVERY: Duration = Duration::from_millis(500);

/// Builds a [`ViewServer`].
#[derive(Debug, Clone)]
pub struct ViewServerBuilder {
    domain: String,
    host: String,
    port: u16,
}

impl ViewServerBuilder {
    /// The address to listen on (default `127.0.0.1`, where Foxglove connects by
    /// default).
    pub fn host(mut self, host: impl Into<String>) -> Self {
        self.host = host.into();
        self
    }

    /// The port (default 8765, Foxglove's; 0 picks a free one).
    pub fn port(mut self, port: u16) -> Self {
        self.port = port;
        self
    }

    /// Connects to the domain and starts serving.
    pub fn start(self) -> anyhow::Result<ViewServer> {
        let esgm = ShmEsgm::builder()
            .domain(&self.domain)
            .host(format!("esgm-view-{}", std::process::id()))
            .timeout(Duration::from_secs(5))
            .connect()
            .with_context(|| format!("cannot reach the system `{}`", self.domain))?;
        let context = Context::new();
        let state = Arc::new(State {
            esgm,
            context: Arc::clone(&context),
            channels: Mutex::new(HashMap::new()),
            server: OnceLock::new(),
            counters: Arc::new(Counters::default()),
        });
        // Weak: the server holds its listener for its life, and the state holds the
        // server; a strong reference would keep both, and the connection, for ever.
        let listener = Arc::new(Listener(Arc::downgrade(&state)));
        // The SDK's server listens on loopback, on a port of its own; clients come in
        // through the door on the address asked for, which accepts both names of the
        // protocol ([`crate::door`]).
        let handle = WebSocketServer::new()
            .name(format!("esgm {}", self.domain))
            .bind("127.0.0.1", 0)
            .capabilities([Capability::Time])
            .context(&context)
            .listener(listener)
            .start_blocking()
            .context("cannot start the Foxglove server on loopback")?;
        let door =
            Door::open(&self.host, self.port, SocketAddr::from(([127, 0, 0, 1], handle.port())))?;
        // Set once, here: the listener and the discovery thread only read it.
        if state.server.set(handle).is_err() {
            anyhow::bail!("the server of `{}` was started twice", self.domain);
        }
        let stop = Arc::new(AtomicBool::new(false));
        let discovery = {
            let (state, stop) = (Arc::clone(&state), Arc::clone(&stop));
            std::thread::Builder::new()
                .name("esgm-view-discovery".into())
                .spawn(move || discover(&state, &stop))
                .context("starting the discovery thread")?
        };
        state.follow();
        Ok(ViewServer { door, state, stop, discovery: Some(discovery) })
    }
}

/// A running server; dropping it stops it.
pub struct ViewServer {
    /// First: dropped first, so the public port closes before the rest stops.
    door: Door,
    state: Arc<State>,
    stop: Arc<AtomicBool>,
    discovery: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for ViewServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ViewServer").field("port", &self.door.port()).finish()
    }
}

impl ViewServer {
    /// A server for `domain`.
    pub fn builder(domain: &str) -> ViewServerBuilder {
        ViewServerBuilder { domain: domain.to_owned(), host: "127.0.0.1".into(), port: 8765 }
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.door.port()
    }

    /// The trajectories with a channel now, by name (once, with or without a trace
    /// channel).
    pub fn channels(&self) -> Vec<String> {
        let mut names: Vec<String> =
            self.state.channels.lock().values().map(|c| c.trajectory.clone()).collect();
        names.sort();
        names.dedup();
        names
    }

    /// The trajectories being forwarded now (watched by at least one client).
    pub fn forwarding(&self) -> Vec<String> {
        let mut names: Vec<String> = self
            .state
            .channels
            .lock()
            .values()
            .filter(|c| c.forwarder.is_some())
            .map(|c| c.trajectory.clone())
            .collect();
        names.sort();
        names
    }

    /// Messages sent since the start.
    pub fn sent(&self) -> u64 {
        self.state.counters.sent.load(Ordering::Relaxed)
    }
}

impl Drop for ViewServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.discovery.take()
            && t.join().is_err()
        {
            tracing::error!("the discovery thread panicked");
        }
        // Forwarders stop before the connection they read through goes.
        self.state.channels.lock().clear();
        if let Some(server) = self.state.server.get() {
            server.broadcast_time(0);
        }
    }
}

/// One channel of a trajectory: its structures, or their traces.
struct Watched {
    trajectory: String,
    shown: Shown,
    channel: Arc<RawChannel>,
    subscribers: usize,
    forwarder: Option<Forwarder>,
}

struct State {
    esgm: ShmEsgm,
    context: Arc<Context>,
    channels: Mutex<HashMap<ChannelId, Watched>>,
    server: OnceLock<WebSocketServerHandle>,
    counters: Arc<Counters>,
}

impl Drop for State {
    /// Stops the WebSocket server (its port is free again, its clients' tasks are
    /// aborted) before the connection goes.
    fn drop(&mut self) {
        if let Some(server) = self.server.take() {
            drop(server.stop());
        }
    }
}

impl State {
    /// Creates channels for new trajectories and closes those of trajectories gone.
    fn follow(&self) {
        // A listing the coordinator did not give changes nothing: the channels stay
        // until a listing says their trajectory is gone.
        let listed = match self.esgm.trajectories() {
            Ok(listed) => listed,
            Err(e) => {
                tracing::warn!(error = %e, "cannot list the trajectories; channels kept as they are");
                return;
            }
        };
        let mut channels = self.channels.lock();
        channels.retain(|_, w| {
            let keep = listed.iter().any(|i| i.name == w.trajectory);
            if !keep {
                tracing::info!(trajectory = %w.trajectory, "trajectory gone: channel closed");
                w.channel.close();
            }
            keep
        });
        for info in listed {
            // Every trajectory's structures; a produced one's traces too.
            let produced =
                !matches!(info.kind, TrajectoryKind::Primitive | TrajectoryKind::Sampled);
            let mut wanted = vec![false];
            if produced {
                wanted.push(true);
            }
            for trace in wanted {
                let has =
                    |w: &Watched| w.trajectory == info.name && (w.shown == Shown::Trace) == trace;
                if channels.values().any(has) {
                    continue;
                }
                let made = if trace {
                    self.trace_channel(&info.name).map(|c| (Shown::Trace, c))
                } else {
                    self.channel(&info.name, &info.type_name)
                        .map(|(e, c)| (Shown::Structures(e), c))
                };
                match made {
                    Ok((shown, channel)) => {
                        tracing::info!(trajectory = %info.name, trace, "channel created");
                        channels.insert(
                            channel.id(),
                            Watched {
                                trajectory: info.name.clone(),
                                shown,
                                channel,
                                subscribers: 0,
                                forwarder: None,
                            },
                        );
                    }
                    Err(e) => tracing::warn!(trajectory = %info.name, "no channel: {e:#}"),
                }
            }
        }
    }

    /// The channel of a produced trajectory's traces ([`crate::trace_view`]).
    fn trace_channel(&self, name: &str) -> anyhow::Result<Arc<RawChannel>> {
        Ok(ChannelBuilder::new(trace_view::topic(name))
            .message_encoding("json")
            .schema(Schema::new(trace_view::SCHEMA_NAME, "jsonschema", trace_view::schema()))
            .context(&self.context)
            .build_raw()?)
    }

    fn channel(&self, name: &str, type_name: &str) -> anyhow::Result<(Encoding, Arc<RawChannel>)> {
        let ty = self.esgm.get_entity_structure_type(type_name)?;
        // A nested type the registry cannot give is left out of the schema, with a warning.
        let lookup = |n: &str| {
            self.esgm
                .get_entity_structure_type(n)
                .inspect_err(|e| {
                    tracing::warn!(type_name = n, error = %e,
                        "a nested type is left out of the schema")
                })
                .ok()
        };
        let (encoding, schema) = Encoding::of(&ty, &lookup);
        let channel = ChannelBuilder::new(format!("/{name}"))
            .message_encoding(schema.message_encoding)
            .schema(Schema::new(schema.name, schema.encoding, schema.data))
            .context(&self.context)
            .build_raw()?;
        Ok((encoding, channel))
    }

    /// The server's time follows the latest valid time forwarded.
    fn broadcast_time(&self) {
        let t = self.counters.latest_valid_time.load(Ordering::Relaxed);
        if let (Some(server), true) = (self.server.get(), t > 0) {
            server.broadcast_time(t);
        }
    }
}

fn discover(state: &State, stop: &AtomicBool) {
    while !stop.load(Ordering::Acquire) {
        std::thread::sleep(DISCOVERY);
        state.follow();
        state.broadcast_time();
    }
}

/// The server's callbacks, on the state while it lives (a client's last messages
/// after the server was dropped find it gone).
struct Listener(Weak<State>);

impl ServerListener for Listener {
    fn on_subscribe(&self, _client: Client, channel: ChannelView) {
        let Some(state) = self.0.upgrade() else { return };
        let mut channels = state.channels.lock();
        let Some(w) = channels.get_mut(&channel.id()) else { return };
        w.subscribers += 1;
        if w.forwarder.is_none() {
            tracing::info!(trajectory = %w.trajectory, "watched: forwarding");
            // The forwarder opens the trajectory on its own thread: this callback
            // runs on the server's and must not wait.
            w.forwarder = Some(Forwarder::start(
                state.esgm.clone(),
                w.trajectory.clone(),
                w.shown,
                Arc::clone(&w.channel),
                Arc::clone(&state.counters),
            ));
        }
    }

    fn on_unsubscribe(&self, _client: Client, channel: ChannelView) {
        let Some(state) = self.0.upgrade() else { return };
        let forwarder = {
            let mut channels = state.channels.lock();
            let Some(w) = channels.get_mut(&channel.id()) else { return };
            w.subscribers = w.subscribers.saturating_sub(1);
            if w.subscribers > 0 {
                return;
            }
            tracing::info!(trajectory = %w.trajectory, "unwatched: stopped");
            w.forwarder.take().inspect(Forwarder::stop)
        };
        // Joined outside the lock, on a thread of its own: this callback must not wait.
        if let Some(f) = forwarder {
            std::thread::spawn(move || drop(f));
        }
    }
}
