//! The importing half: trajectories of other domains, received from Zenoh and written
//! into ordinary primitive trajectories of the local domain, whose writer is this
//! bridge.
//!
//! Per `--import` key expression, one thread subscribes to the key and asks the
//! exporters what it matches (`?esgm=meta`, again every [`DISCOVER_EVERY`] for new
//! trajectories). For each trajectory it registers the type (or refuses it, naming the
//! attribute that differs: [`crate::types`]), creates the local trajectory with the
//! exporter's cache, and takes the exporter's history (`?esgm=history`) before the
//! stream. Each message is validated (header, then `codec::access` through
//! `decode_bytes`); a malformed one is counted and dropped.
//!
//! **One wake-up per message.** A message of a trajectory already imported is added
//! on Zenoh's receive thread, in the subscriber's callback: handing it to the import
//! thread through a channel cost a second wake-up per message, about a fifth of the
//! bridge's latency on two cores (issue 27). Only what needs a Zenoh query first (a
//! trajectory not known yet, a new exporter session, a changed type) goes to the
//! import thread, which may wait for the reply; the callback never does, since the
//! reply comes through the very thread it runs on. The callback never waits for the
//! import thread either: while that thread holds the importer (a query, a history),
//! messages queue for it, and once one message waits there every later one does, so a
//! trajectory's messages are added in the order they came.
//!
//! **Times.** The structure keeps its valid and create times; the add time is the
//! local gate's, so the local trajectory's add delay (`esgm hz`, `esgm stats`) is the
//! delay from the valid time to arrival here, across hosts.
//!
//! **Losses.** Messages carry the writer's sequence numbers (per writer). A jump is
//! samples lost — minus those the exporter skipped on purpose (`--latest-only`,
//! `--max-rate`), which it counts in the header — and counted per cause: within one
//! run of the exporter, a sequence gap; across a restart of it (a new session), what
//! its history did not give back. Losses are also counted in the local trajectory's
//! stats as `lost`.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use esgm_core::esgm::TrajectorySpec;
use esgm_core::{
    AddOutcome, CreateError, EntityStructure, EntityTrajectoryStructure, Esgm, FluentStreamPolicy,
    InProcessTrajectory,
};
use esgm_shm::ShmEsgm;
use parking_lot::Mutex;
use zenoh::Wait as _;

use crate::ask::ask;
use crate::key::{self, Ask};
use crate::stats::{LossCause, Stats};
use crate::types;
use crate::wire::{self, Header, Meta};

/// How often an importer asks what its key expression matches.
pub const DISCOVER_EVERY: Duration = Duration::from_secs(1);
/// How long a meta or history query may take.
const QUERY_TIMEOUT: Duration = Duration::from_secs(2);

/// What every importer of a bridge shares.
#[derive(Debug, Clone)]
pub struct ImportSite {
    /// The local domain.
    pub domain: String,
    /// The local connection (types, trajectories).
    pub esgm: ShmEsgm,
    /// The Zenoh session.
    pub session: zenoh::Session,
    /// Counters.
    pub stats: Stats,
    /// Set when the bridge stops.
    pub stop: Arc<AtomicBool>,
}

/// One imported trajectory.
#[derive(Debug)]
struct Imported {
    remote: String,
    handle: InProcessTrajectory,
    type_hash: u64,
    /// The exporter session whose messages arrive now.
    session: u64,
    /// The last sample added: its writer, sequence, the exporter's skipped count then,
    /// and the exporter session it came from.
    last: Option<(u64, u64, u64, u64)>,
}

/// Whether handling a message may wait for a Zenoh query (meta, history).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Queries {
    /// On the import thread.
    Allowed,
    /// On Zenoh's receive thread, which would have to deliver the reply itself.
    Forbidden,
}

/// What became of a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Handled {
    /// Added, counted or dropped.
    Done,
    /// Untouched: it needs a query first (only with [`Queries::Forbidden`]).
    NeedsQuery,
}

/// The messages the receive thread left to the import thread, and how many of them
/// are not handled yet (while any is, the callback leaves every message to the thread).
struct Backlog {
    sender: mpsc::Sender<(String, Vec<u8>)>,
    waiting: AtomicUsize,
}

impl Backlog {
    fn push(&self, key: &str, payload: Vec<u8>) {
        self.waiting.fetch_add(1, Ordering::AcqRel);
        if self.sender.send((key.to_owned(), payload)).is_err() {
            // The import thread ended: the bridge is stopping.
            self.waiting.fetch_sub(1, Ordering::AcqRel);
        }
    }
}

/// Starts importing what `key_expr` matches, on its own thread, until `site.stop`.
pub fn spawn(site: ImportSite, key_expr: String) -> anyhow::Result<std::thread::JoinHandle<()>> {
    let stop = Arc::clone(&site.stop);
    let importer =
        Arc::new(Mutex::new(Importer { site, imports: HashMap::new(), refused: HashMap::new() }));
    let (sender, backlog_rx) = mpsc::channel();
    let backlog = Arc::new(Backlog { sender, waiting: AtomicUsize::new(0) });
    let subscriber = {
        let importer = Arc::clone(&importer);
        let backlog = Arc::clone(&backlog);
        let session = importer.lock().site.session.clone();
        session
            .declare_subscriber(key_expr.clone())
            .callback(move |sample| {
                let key = sample.key_expr().as_str();
                let payload = sample.payload().to_bytes();
                // Checked under the importer's lock: the import thread takes a message
                // off the backlog and handles it under that lock, so `waiting` is 0 here
                // only once every message before this one was handled.
                if let Some(mut importer) = importer.try_lock() {
                    if backlog.waiting.load(Ordering::Acquire) == 0
                        && importer.message(key, &payload, Queries::Forbidden) == Handled::Done
                    {
                        return;
                    }
                    backlog.push(key, payload.into_owned());
                    return;
                }
                backlog.push(key, payload.into_owned());
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("zenoh subscriber on `{key_expr}`: {e}"))?
    };
    let thread =
        std::thread::Builder::new().name(format!("import-{key_expr}")).spawn(move || {
            let span = tracing::info_span!("import", key = %key_expr);
            let _entered = span.enter();
            // Undeclared when this thread ends.
            let _subscriber = subscriber;
            let mut discovered = Instant::now() - DISCOVER_EVERY;
            while !stop.load(Ordering::Relaxed) {
                if discovered.elapsed() >= DISCOVER_EVERY {
                    importer.lock().discover(&key_expr);
                    discovered = Instant::now();
                }
                match backlog_rx.recv_timeout(Duration::from_millis(100)) {
                    Ok((key, payload)) => {
                        let mut importer = importer.lock();
                        importer.message(&key, &payload, Queries::Allowed);
                        backlog.waiting.fetch_sub(1, Ordering::AcqRel);
                    }
                    // The callback holds a sender as long as the subscriber lives.
                    Err(mpsc::RecvTimeoutError::Timeout | mpsc::RecvTimeoutError::Disconnected) => {
                    }
                }
            }
        })?;
    Ok(thread)
}

struct Importer {
    site: ImportSite,
    imports: HashMap<(String, String), Imported>,
    /// Trajectories refused (type conflict), with the reason.
    refused: HashMap<(String, String), String>,
}

impl Importer {
    fn count(
        &self,
        domain: &str,
        name: &str,
        f: impl FnOnce(&mut crate::stats::TrajectoryCounters),
    ) {
        self.site.stats.with("import", domain, name, f);
    }

    /// Asks what `key_expr` matches and sets up the trajectories not imported yet.
    fn discover(&mut self, key_expr: &str) {
        let answers = match ask(&self.site.session, key_expr, Ask::Meta, &[], QUERY_TIMEOUT) {
            Ok(a) => a,
            Err(e) => {
                tracing::warn!(error = %e, "meta query failed");
                return;
            }
        };
        for answer in answers.ok {
            let Ok(meta) = serde_json::from_slice::<Meta>(&answer.payload) else {
                tracing::warn!(key = %answer.key, "an unreadable meta reply");
                continue;
            };
            let id = (meta.domain.clone(), meta.trajectory.clone());
            if meta.domain == self.site.domain || self.refused.contains_key(&id) {
                continue;
            }
            match self.imports.get_mut(&id) {
                Some(i) if i.type_hash == meta.type_hash => {
                    if i.session != meta.session {
                        // The exporter restarted: what it has kept, before its stream.
                        i.session = meta.session;
                        self.history(&id);
                    }
                }
                _ => self.setup(meta),
            }
        }
    }

    /// Registers the type, creates the local trajectory and takes the history.
    fn setup(&mut self, meta: Meta) {
        let id = (meta.domain.clone(), meta.trajectory.clone());
        let remote = format!("{}/{}", meta.domain, meta.trajectory);
        match self.create(&meta, &remote) {
            Ok(handle) => {
                tracing::info!(%remote, local = %meta.trajectory, "importing");
                let session = meta.session;
                let previous = self.imports.remove(&id);
                let imported = Imported {
                    remote,
                    handle,
                    type_hash: meta.type_hash,
                    session,
                    last: previous.and_then(|p| p.last),
                };
                self.imports.insert(id.clone(), imported);
                self.history(&id);
            }
            Err(reason) => {
                eprintln!("esgm-bridge: import of `{remote}` refused: {reason}");
                tracing::error!(%remote, %reason, "import refused");
                self.count(&id.0, &id.1, |c| c.error = Some(reason.clone()));
                self.refused.insert(id, reason);
            }
        }
    }

    fn create(&self, meta: &Meta, remote: &str) -> Result<InProcessTrajectory, String> {
        let esgm = &self.site.esgm;
        types::register(esgm, remote, &meta.type_name, &meta.types).map_err(|e| e.to_string())?;
        let spec = TrajectorySpec::primitive(meta.trajectory.clone(), meta.type_name.clone())
            .policy(FluentStreamPolicy::default().cache(meta.cache));
        match esgm.create_trajectory(spec) {
            Ok(h) => Ok(h),
            Err(CreateError::EntityStructureAlreadyExists { .. }) => {
                let h = esgm
                    .get_entity_trajectory_structure(&meta.trajectory)
                    .map_err(|e| e.to_string())?;
                let local = h.entity_type().map_err(|e| e.to_string())?;
                if local.name != meta.type_name {
                    return Err(format!(
                        "a local trajectory `{}` of type `{}` exists (the remote one is `{}`)",
                        meta.trajectory, local.name, meta.type_name
                    ));
                }
                Ok(h)
            }
            Err(e) => Err(e.to_string()),
        }
    }

    /// Takes the exporter's history of `id` (oldest first) into the trajectory.
    fn history(&mut self, id: &(String, String)) {
        let key = key::data_key(&id.0, &id.1);
        let answers = match ask(&self.site.session, &key, Ask::History, &[], QUERY_TIMEOUT) {
            Ok(a) => a,
            Err(e) => {
                tracing::warn!(error = %e, %key, "history query failed");
                return;
            }
        };
        for answer in answers.ok {
            self.decoded(&id.0, &id.1, &answer.payload, true, Queries::Allowed);
        }
    }

    /// A message on the data key. With [`Queries::Forbidden`], one that needs a query
    /// first is left untouched ([`Handled::NeedsQuery`]).
    fn message(&mut self, key: &str, payload: &[u8], queries: Queries) -> Handled {
        let Some((domain, name)) = key::parse(key) else {
            tracing::debug!(%key, "a message on a key that names no trajectory");
            return Handled::Done;
        };
        if domain == self.site.domain {
            return Handled::Done;
        }
        let id = (domain.to_owned(), name.to_owned());
        if self.refused.contains_key(&id) {
            self.count(domain, name, |c| c.refused += 1);
            return Handled::Done;
        }
        if !self.imports.contains_key(&id) {
            if queries == Queries::Forbidden {
                return Handled::NeedsQuery;
            }
            // Not known yet: ask this one key (its history then covers this message).
            self.discover(key);
            return Handled::Done;
        }
        self.decoded(domain, name, payload, false, queries)
    }

    /// Validates a message and adds its structure.
    fn decoded(
        &mut self,
        domain: &str,
        name: &str,
        payload: &[u8],
        from_history: bool,
        queries: Queries,
    ) -> Handled {
        let (header, es) = match wire::decode(payload) {
            Ok(m) => m,
            Err(e) => {
                tracing::warn!(trajectory = %name, error = %e, "malformed message dropped");
                self.count(domain, name, |c| {
                    c.malformed += 1;
                    c.error = Some(e.to_string());
                });
                return Handled::Done;
            }
        };
        let id = (domain.to_owned(), name.to_owned());
        let Some(imported) = self.imports.get(&id) else { return Handled::Done };
        let type_changed = header.type_hash != imported.type_hash;
        let session_changed = !from_history && imported.session != header.session;
        if (type_changed || session_changed) && queries == Queries::Forbidden {
            return Handled::NeedsQuery;
        }
        if type_changed {
            // The exporter's type changed (or the message lies): ask again.
            self.discover(&key::data_key(domain, name));
            if self.imports.get(&id).is_none_or(|i| i.type_hash != header.type_hash) {
                self.count(domain, name, |c| c.refused += 1);
                return Handled::Done;
            }
        }
        if !from_history {
            let session_changed =
                self.imports.get(&id).is_some_and(|i| i.session != header.session);
            if session_changed {
                // The exporter restarted (or another one took over): its history first.
                if let Some(i) = self.imports.get_mut(&id) {
                    i.session = header.session;
                }
                self.history(&id);
            }
        }
        if let Some(imported) = self.imports.get_mut(&id) {
            apply(imported, &self.site.stats, domain, name, &header, es);
        }
        Handled::Done
    }
}

/// Counts what the sequence says and adds the structure.
fn apply(
    imported: &mut Imported,
    stats: &Stats,
    domain: &str,
    name: &str,
    header: &Header,
    es: Option<EntityStructure>,
) {
    tracing::debug!(writer = header.writer, sequence = header.sequence, session = header.session,
        last = ?imported.last, "received");
    let mut lost = None;
    let mut skipped = 0;
    if let Some((writer, sequence, last_skipped, session)) = imported.last {
        if writer == header.writer {
            if header.sequence <= sequence {
                stats.with("import", domain, name, |c| {
                    c.messages += 1;
                    c.duplicates += 1;
                });
                return;
            }
            let gap = header.sequence - sequence - 1;
            if session == header.session {
                skipped = header.skipped.saturating_sub(last_skipped).min(gap);
            }
            if gap > skipped {
                let cause = if session == header.session {
                    LossCause::SequenceGap
                } else {
                    LossCause::ExporterRestarted
                };
                lost = Some((cause, gap - skipped));
            }
        }
    }
    imported.last = Some((header.writer, header.sequence, header.skipped, header.session));
    if let Some((cause, n)) = lost {
        tracing::warn!(remote = %imported.remote, lost = n, ?cause, "samples lost on the way");
        if let Err(e) = imported.handle.with_store(|s| s.replicate_loss(n)) {
            tracing::warn!(error = %e, "the local trajectory is gone");
        }
    }
    let Some(es) = es else {
        // The writer reset its trajectory: so does this one.
        if let Err(e) = imported.handle.reset() {
            tracing::warn!(error = %e, "could not reset the local trajectory");
        }
        stats.with("import", domain, name, |c| {
            c.messages += 1;
            if let Some((cause, n)) = lost {
                let count = c.lost.entry(cause).or_default();
                *count = count.saturating_add(n);
            }
        });
        return;
    };
    // Entered with the lineage it had where it was made: its inputs are named as the
    // exporting domain names them.
    let lineage = header.lineage.clone().map(Arc::new);
    let outcome = imported.handle.add_produced(es, lineage);
    stats.with("import", domain, name, |c| {
        c.messages += 1;
        // Gaps come from the network: two hostile messages must not overflow the sums.
        c.skipped = c.skipped.saturating_add(skipped);
        if let Some((cause, n)) = lost {
            let count = c.lost.entry(cause).or_default();
            *count = count.saturating_add(n);
        }
        match outcome {
            Ok(AddOutcome::Added | AddOutcome::Held { .. } | AddOutcome::Forwarded) => c.added += 1,
            Ok(AddOutcome::Dropped(v)) => {
                c.dropped += 1;
                c.error = Some(v.to_string());
            }
            Err(e) => {
                c.dropped += 1;
                c.error = Some(e.to_string());
            }
        }
    });
}
