//! The exporting half: a trajectory of the local domain, read from its shared-memory
//! service, published on Zenoh.
//!
//! The exporter subscribes to the trajectory's iceoryx2 service itself (not to a
//! replica), for two reasons: the codec bytes go on the wire exactly as the writer put
//! them in shared memory (validated by the subscriber, never decoded and re-encoded),
//! and the writer's own sequence numbers travel with them, so the importer counts
//! every sample the writer admitted that never arrived — also across a restart of this
//! bridge, which a count of its own could not see.
//!
//! It keeps the last samples up to the trajectory's cache bound, as sent, for late
//! joiners ([`crate::serve`]).

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use esgm_core::EntityStructureType;
use esgm_shm::control::{Request, Response, TrajectoryRecord};
use esgm_shm::{Decided, ReceiveError, ShmEsgm, ShmService, TrajectorySubscriber, WriterCheck};
use iceoryx2::prelude::NodeBuilder;
use parking_lot::Mutex;
use zenoh::Wait as _;
use zenoh::bytes::ZBytes;
use zenoh::qos::CongestionControl;

use crate::key;
use crate::stats::Stats;
use crate::wire::{self, Header, Kind, Meta};

/// How often an exporter checks that its trajectory is still the same generation.
const RECHECK: Duration = Duration::from_secs(1);

/// One trajectory to export, with its flow options.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportOptions {
    /// The trajectory.
    pub name: String,
    /// Send only the newest sample when several are waiting; count the others skipped.
    pub latest_only: bool,
    /// At most this many samples per second; the newest waiting one is sent when the
    /// time comes, the others are counted skipped.
    pub max_rate: Option<f64>,
}

/// What the bridge serves about one exported trajectory: its type and cache, and the
/// last messages sent, for late joiners.
#[derive(Debug)]
pub struct Exported {
    /// Type, cache and session, as `?esgm=meta` answers them.
    pub meta: Meta,
    /// The last messages sent, oldest first, at most `bound`.
    pub history: VecDeque<ZBytes>,
    /// The cache bound.
    pub bound: usize,
}

/// Every exported trajectory, by name (shared with the queryable).
pub type Catalog = Arc<Mutex<std::collections::BTreeMap<String, Exported>>>;

/// What every exporter of a bridge shares.
#[derive(Debug, Clone)]
pub struct ExportSite {
    /// The local domain.
    pub domain: String,
    /// The local connection (control requests).
    pub esgm: ShmEsgm,
    /// The Zenoh session.
    pub session: zenoh::Session,
    /// Random per run of this bridge.
    pub session_id: u64,
    /// What the queryable serves.
    pub catalog: Catalog,
    /// Counters.
    pub stats: Stats,
    /// Set when the bridge stops.
    pub stop: Arc<AtomicBool>,
}

/// The trajectory's registry record, if it exists.
pub fn lookup(esgm: &ShmEsgm, name: &str) -> anyhow::Result<TrajectoryRecord> {
    match esgm.control(Request::GetEntityTrajectoryStructure { name: name.to_owned() })? {
        Response::Trajectory(record) => Ok(*record),
        other => anyhow::bail!("unexpected answer from the coordinator: {other:?}"),
    }
}

/// Folds iceoryx2's 128-bit publisher id into the header's 64 bits.
fn writer_id(id: u128) -> u64 {
    (id as u64) ^ ((id >> 64) as u64)
}

/// Starts exporting `options.name` on its own thread; it runs until `site.stop`.
pub fn spawn(
    site: ExportSite,
    options: ExportOptions,
) -> std::io::Result<std::thread::JoinHandle<()>> {
    std::thread::Builder::new().name(format!("export-{}", options.name)).spawn(move || {
        let span = tracing::info_span!("export", trajectory = %options.name);
        let _entered = span.enter();
        let mut reported = None::<String>;
        while !site.stop.load(Ordering::Relaxed) {
            if let Err(e) = export_generation(&site, &options) {
                let message = format!("{e:#}");
                if reported.as_ref() != Some(&message) {
                    tracing::warn!(error = %message, "not exported (retrying)");
                    reported = Some(message.clone());
                }
                site.stats.with("export", &site.domain, &options.name, |c| c.error = Some(message));
                std::thread::sleep(Duration::from_millis(300));
            }
        }
    })
}

/// Exports one generation of the trajectory, until it changes or the bridge stops.
fn export_generation(site: &ExportSite, options: &ExportOptions) -> anyhow::Result<()> {
    let name = &options.name;
    let record = lookup(&site.esgm, name)?;
    let type_name = record.info.type_name.clone();
    let entity_type = record
        .types
        .iter()
        .find(|(n, _)| *n == type_name)
        .map_or_else(|| EntityStructureType::new(""), |(_, t)| t.clone());
    // The writer's and every reader's settings: whoever opens the service first
    // creates it with them, and the others' requests fit.
    let qos = esgm_shm::trajectory_qos(&record.info.policy, &entity_type, record.readers);
    let bound = qos.history_size;
    // esgm's node settings: no scan of every node of the host at each node and each
    // service opened (a crashed reader's room is reclaimed when it is needed).
    let node = NodeBuilder::new()
        .config(&esgm_shm::node_config(esgm_shm::Cleanup::None))
        .name(&esgm_shm::node_name(
            &site.domain,
            &format!("bridge-{}/export/{name}", std::process::id()),
        ))
        .create::<ShmService>()
        .map_err(|e| anyhow::anyhow!("iceoryx2 node: {e:?}"))?;
    // The services of one generation of a trajectory live in `<domain>.g<generation>`
    // (esgm-shm's `settings::generation_domain`).
    let subscriber = TrajectorySubscriber::builder(name.clone(), type_name.clone())
        .domain(format!("{}.g{}", site.domain, record.generation))
        .qos(qos)
        .create(&node)?;
    let key = key::data_key(&site.domain, name);
    let publisher = site
        .session
        .declare_publisher(key.clone())
        .congestion_control(CongestionControl::Block)
        .express(true)
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh publisher on `{key}`: {e}"))?;
    let type_hash = wire::type_hash(&record.types);
    let meta = Meta {
        domain: site.domain.clone(),
        trajectory: name.clone(),
        type_name: type_name.clone(),
        types: record.types.clone(),
        type_hash,
        cache: record.info.policy.cache,
        session: site.session_id,
    };
    site.catalog.lock().insert(name.clone(), Exported { meta, history: VecDeque::new(), bound });
    site.stats.with("export", &site.domain, name, |c| c.error = None);
    tracing::info!(key = %key, generation = record.generation, "exporting");

    // A rate whose period cannot be a duration was refused when parsed; one reaching
    // here anyway (a library caller) means no limit rather than a panic.
    let interval = options.max_rate.and_then(|r| esgm_core::time::period_from_rate(r).ok());
    let mut flow = Flow {
        check: WriterCheck::new(record.port.map(|p| p.publisher)),
        throttled: options.latest_only || interval.is_some(),
        queue: VecDeque::new(),
        skipped: 0,
        type_hash,
        type_name,
        session: site.session_id,
    };
    let mut next_allowed = Instant::now();
    let mut checked = Instant::now();
    loop {
        if site.stop.load(Ordering::Relaxed) {
            return Ok(());
        }
        // A sample from a port the registry has not named yet (a writer that just
        // started or restarted) is held, and the registry asked soon.
        let recheck = if flow.check.awaits_writer() { VERIFY_WRITER } else { RECHECK };
        if checked.elapsed() >= recheck {
            checked = Instant::now();
            match lookup(&site.esgm, name) {
                Ok(r) if r.generation == record.generation => {
                    flow.set_writer(r.port.map(|p| p.publisher));
                    let not_writer = flow.check.not_writer();
                    site.stats.with("export", &site.domain, name, |c| c.not_writer = not_writer);
                }
                _ => {
                    site.catalog.lock().remove(name);
                    anyhow::bail!("trajectory `{name}` was destroyed or re-pointed");
                }
            }
        }
        if flow.queue.is_empty() || Instant::now() < next_allowed {
            let wait = if flow.queue.is_empty() {
                Duration::from_millis(100)
            } else {
                next_allowed.saturating_duration_since(Instant::now())
            };
            let first = subscriber.wait_for_sample(wait);
            flow.take(first);
        }
        // Everything waiting, at once: the shared-memory queue is as long as the
        // trajectory's history, and a writer's burst must not overrun it while this
        // thread is in a Zenoh put.
        loop {
            let next = subscriber.receive();
            if matches!(next, Ok(None)) {
                break;
            }
            flow.take(next);
        }
        if flow.throttled && flow.queue.len() > 1 {
            // The newest only, behind a reset if one is waiting (a reset clears the
            // queue, so it can only be first).
            let newest = flow.queue.pop_back();
            let reset = flow.queue.pop_front().filter(|m| wire::is_reset(m));
            flow.skipped += flow.queue.len() as u64 + u64::from(reset.is_none());
            flow.queue.clear();
            flow.queue.extend(reset.into_iter().chain(newest));
        }
        if Instant::now() < next_allowed {
            continue;
        }
        let Some(mut message) = flow.queue.pop_front() else { continue };
        wire::set_skipped(&mut message, flow.skipped);
        let payload = ZBytes::from(message);
        if let Some(exported) = site.catalog.lock().get_mut(name) {
            if exported.history.len() >= exported.bound {
                exported.history.pop_front();
            }
            exported.history.push_back(payload.clone());
        }
        publisher.put(payload).wait().map_err(|e| anyhow::anyhow!("zenoh put on `{key}`: {e}"))?;
        site.stats.with("export", &site.domain, name, |c| {
            c.messages += 1;
            c.skipped = flow.skipped;
        });
        if let Some(i) = interval {
            next_allowed = Instant::now() + i;
        }
    }
}

/// How soon an exporter holding samples from an unnamed port asks the registry again.
const VERIFY_WRITER: Duration = Duration::from_millis(100);

/// What an exporter has taken from shared memory and not sent yet.
struct Flow {
    /// Only the writer's samples are sent, as every esgm reader checks
    /// ([`WriterCheck`]: held until the registry names the writer's port).
    check: WriterCheck<Vec<u8>>,
    /// `--latest-only` or `--max-rate`: only the newest waiting message is sent.
    throttled: bool,
    /// Messages made, oldest first (the codec bytes are copied out of shared memory at
    /// once, so the writer's samples go back to it).
    queue: VecDeque<Vec<u8>>,
    /// Samples not sent on purpose so far.
    skipped: u64,
    type_hash: u64,
    type_name: String,
    session: u64,
}

impl Flow {
    /// The registry names `port` as the writer's (`None`: not yet): held messages from
    /// it are queued, in order, the others dropped and counted.
    fn set_writer(&mut self, port: Option<u128>) {
        for decided in self.check.set_writer(port) {
            self.decide(decided);
        }
    }

    fn decide(&mut self, decided: Decided<Vec<u8>>) {
        match decided {
            Decided::Enter { item, lost } => {
                // Samples the shared-memory queue overwrote while this exporter waited
                // are, with a rate limit, not sent by choice too; without one the
                // importer counts them from the sequence numbers.
                if self.throttled {
                    self.skipped = self.skipped.saturating_add(lost);
                }
                self.queue_message(item);
            }
            Decided::NotWriter { port, .. } => {
                if self.check.not_writer() == 1 {
                    tracing::warn!(publisher = %format!("{port:#x}"),
                        "a sample from a port that is not the writer's was not exported (later ones are counted)");
                }
            }
        }
    }

    /// Queues a message of the writer's (a reset clears what waits before it).
    fn queue_message(&mut self, message: Vec<u8>) {
        if wire::is_reset(&message) {
            // A reset is never skipped: what came before it is gone everywhere.
            self.queue.clear();
        }
        self.queue.push_back(message);
    }

    fn take(&mut self, received: Result<Option<esgm_shm::ReceivedSample>, ReceiveError>) {
        let port = match &received {
            Ok(Some(sample)) => sample.publisher_id().value(),
            Err(ReceiveError::Reset { publisher, .. }) => publisher.value(),
            _ => 0,
        };
        let (writer, sequence, add_time, kind, bytes) = match &received {
            Ok(Some(sample)) => (
                writer_id(sample.publisher_id().value()),
                sample.header().sequence,
                sample.header().add_time,
                Kind::Structure,
                sample.archive_bytes(),
            ),
            Ok(None) => return,
            Err(ReceiveError::Reset { sequence, publisher }) => {
                (writer_id(publisher.value()), *sequence, 0, Kind::Reset, &[][..])
            }
            Err(e) => {
                tracing::warn!(error = %e, "a sample was rejected (counted by the subscriber)");
                return;
            }
        };
        // A lineage the sample carries crosses with it; one that does not read is left
        // behind, said once per sample (the structure itself was validated).
        let lineage = match &received {
            Ok(Some(sample)) => sample.lineage().unwrap_or_else(|e| {
                tracing::warn!(error = %e, "a sample's lineage does not read; sent without it");
                None
            }),
            _ => None,
        };
        let header = Header {
            session: self.session,
            writer,
            sequence,
            add_time,
            skipped: self.skipped,
            type_hash: self.type_hash,
            type_name: self.type_name.clone(),
            kind,
            lineage,
        };
        let message = wire::encode(&header, bytes);
        if let Some(decided) = self.check.arrive(port, sequence, message) {
            self.decide(decided);
        }
    }
}
