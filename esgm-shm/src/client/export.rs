//! The writer's half of mirroring a trajectory: an [`Export`] publishes everything
//! that happens to a trajectory this process writes, from the thread that made it
//! happen.
//!
//! The local store's tap ([`esgm_core::StoreTap`]) is told each event — an entry, a
//! violation, a reset — inline, in stream order, while the store is locked, and
//! publishes it on the trajectory's services at once, stamped with the gate's add
//! time. So a structure added on a user's thread (or emitted by a unit's worker, or
//! sampled by a periodic worker) is in shared memory when `add` returns, and the
//! readers' wake-up is the only one on its way out of this process.
//!
//! A primitive trajectory also has an *inbox* (`<domain>:inbox`): other processes add
//! to it there (see [`super::import`]), and the connection's receiver thread takes
//! their structures and adds them through this process's gate, so one gate orders,
//! checks and counts every process's adds.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use esgm_core::esgm::TrajectoryKind;
use esgm_core::{
    EntityTrajectoryStructure, InProcessTrajectory, Rejection, Sample, SharedStructure, StoreEvent,
    TapId,
};

use parking_lot::Mutex;

use super::blocking_add::{AddServer, BlockingAddError};
use super::image_loans::{Chunk, LoanAllocator, as_loan, loaned_image};
use super::settings::{
    fixed_sample_len, generation_domain, handle_qos, inbox_domain, inbox_qos, join_service,
};
use super::shared_node::SharedNode;
use crate::client::holdings::{HoldingOwner, Holdings};
use crate::control::protocol::TrajectoryRecord;
use crate::data_plane::capacity::{EventCapacity, Readers};
use crate::data_plane::image_loan::ImageChunk;
use crate::data_plane::kept::{KeepError, KeptHistory, KeptImage, KeptLocation, Retention};
use crate::data_plane::publisher::{PublishError, SampleSizing, TrajectoryPublisher};
use crate::data_plane::service::EventSpec;
use crate::data_plane::service::OpenError;
use crate::data_plane::service_name::TrajectoryServiceNames;
use crate::data_plane::subscriber::{ReceiveError, TrajectorySubscriber};
use crate::data_plane::violations::ViolationPublisher;
use crate::data_plane::wait::WaitStrategy;

/// Where an export's violations publisher is opened ([`Outlet::violations`]).
#[derive(Debug)]
struct ViolationSite {
    node: SharedNode,
    /// The generation's domain.
    domain: String,
    trajectory: String,
    readers: Readers,
}

/// An export could not be set up.
#[derive(Debug, thiserror::Error)]
pub(crate) enum ExportError {
    /// The services could not be opened.
    #[error(transparent)]
    Open(#[from] OpenError),
    /// The blocking-add service could not be opened.
    #[error(transparent)]
    Blocking(#[from] BlockingAddError),
    /// The local trajectory was destroyed meanwhile.
    #[error("trajectory `{trajectory}` was destroyed meanwhile")]
    Gone { trajectory: String },
}

/// The ports an export publishes on, shared by the store's tap (any adding thread)
/// and the location thread (which hands late readers their history).
#[derive(Debug)]
pub(crate) struct Outlet {
    publisher: TrajectoryPublisher,
    /// Opened at the first violation: most trajectories never have one, and its ports
    /// and services cost the writer memory and file descriptors (a process writing a
    /// thousand trajectories ran out of the latter).
    violations: Option<ViolationPublisher>,
    /// Where the violations publisher is opened.
    violation_site: ViolationSite,
    /// Trajectories of images: this process's own subscriber, through which the
    /// writer's store reads the images it sent from loans ([`super::image_loans`]).
    own: Option<(TrajectorySubscriber, HoldingOwner)>,
    /// Events that could not be published (the first is logged, all are counted).
    failures: u64,
    /// Entries not published since the store last asked ([`esgm_core::StoreTap`]).
    unpublished: u64,
    /// A primitive trajectory's kept history: every structure that enters is kept
    /// there before it is published, so that it outlives this process (SPEC D1).
    kept: Option<KeptHistory>,
    /// Structures that entered but could not be kept (logged at the 1st, 10th,
    /// 100th…): readers have them, the file does not.
    unkept: u64,
}

impl Outlet {
    /// A loan for an image (the trajectory's [`esgm_core::OctetsAllocator`]): of the
    /// kept history for a kept trajectory, of the publisher otherwise; `None`, logged,
    /// if it cannot lend one now.
    fn loan_image(&mut self, width: i64, height: i64, format: i64) -> Option<Chunk> {
        if let Some(kept) = &mut self.kept {
            let loaned = crate::data_plane::image_layout::pixel_len(width, height, format)
                .map_err(|e| e.to_string())
                .and_then(|len| {
                    KeptImage::loan(kept, (width, height, format), len).map_err(|e| e.to_string())
                });
            return match loaned {
                Ok(image) => Some(Chunk::Kept(image)),
                Err(e) => {
                    tracing::debug!(trajectory = %self.publisher.trajectory(), error = %e,
                        "no room in the kept history for an image; it is written on the heap");
                    None
                }
            };
        }
        self.publisher
            .loan_image_chunk(width, height, format)
            .map(Chunk::Shm)
            .map_err(|e| {
                tracing::debug!(trajectory = %self.publisher.trajectory(), error = %e,
                    "no shared-memory buffer for an image; it is written on the heap")
            })
            .ok()
    }

    /// Publishes an entering structure (and keeps it, for a kept trajectory). One whose
    /// pixels are this outlet's loan is completed in place and sent or kept where it is,
    /// and the structure as this process now reads it is returned, for the store to
    /// keep (see [`super::image_loans`]).
    fn enter(&mut self, sample: &Sample, owner: usize) -> Option<SharedStructure> {
        let es = &sample.structure;
        let loaned = match es.as_owned() {
            Some(owned) => loaned_image(owned, owner),
            None => None,
        };
        let Some(holder) = loaned else {
            self.encode(sample);
            return None;
        };
        let loan = as_loan(&holder)?;
        let Some(chunk) = loan.take() else {
            // Sent before (the same pixels added twice): encode a copy.
            self.encode(sample);
            return None;
        };
        let size = (
            es.get("width").and_then(|v| v.as_long()),
            es.get("height").and_then(|v| v.as_long()),
            es.get("format").and_then(|v| v.as_long()),
        );
        let (w, h, f) = chunk.size();
        if size != (Some(w), Some(h), Some(f)) {
            // The structure says another size than its pixels were loaned for: the
            // reader must get what the structure says, so encode it (a copy).
            loan.rescue();
            drop(chunk);
            self.encode(sample);
            return None;
        }
        let received = match chunk {
            Chunk::Kept(image) => self.keep_image(image, sample),
            Chunk::Shm(chunk) => self.send_image(chunk, sample),
        };
        // Every path that did not send the pixels gives the chunk's memory back; the
        // holder, which the store and the producer still read, takes a copy first (the
        // outlet is locked: no loan has written there yet).
        match received.as_ref().and_then(|r| r.get("image_data")).and_then(|v| v.as_octets()) {
            Some(pixels) => loan.sent(pixels),
            None => loan.rescue(),
        }
        received
    }

    /// Completes an image in its loan of the kept history, keeps it there and publishes
    /// where it is: written once. The structure as this process reads it back in place.
    fn keep_image(&mut self, image: KeptImage, sample: &Sample) -> Option<SharedStructure> {
        let es = &sample.structure;
        let (valid, create) = (es.valid_time(), es.create_time());
        let kept = self.kept.as_mut()?;
        let kept_at = image
            .complete(es.name(), valid, create)
            .map_err(KeepError::from)
            .and_then(|(loan, written)| kept.commit(loan, written, sample.add_time, valid));
        let at = match kept_at {
            Ok(at) => at,
            Err(e) => {
                // Not kept: published in full instead, as any structure that cannot be.
                self.not_kept(&e);
                self.publish_entry(sample);
                return None;
            }
        };
        esgm_core::probe::mark(esgm_core::probe::Step::Kept);
        if let Err(e) = self.publisher.publish_kept(&at, (valid, create), sample.add_time) {
            self.entry_failed(&e);
        }
        if let Some((_, owner)) = &self.own {
            owner.count_sent(true);
        }
        self.kept.as_mut()?.hold_own(&at)
    }

    /// Completes an image in its loan of the publisher and sends it: written once. The
    /// structure as this process received it back through its own subscriber.
    fn send_image(&mut self, chunk: ImageChunk, sample: &Sample) -> Option<SharedStructure> {
        let es = &sample.structure;
        let sent = chunk
            .complete(&self.publisher, es.name(), es.valid_time(), es.create_time())
            .and_then(|loan| loan.send_added(sample.add_time));
        let published = match sent {
            Ok(p) => p,
            Err(e) => {
                self.entry_failed(&e);
                return None;
            }
        };
        if let Some((_, owner)) = &self.own {
            owner.count_sent(true);
        }
        self.receive_own(published.sequence)
    }

    /// Publishes an entering structure by writing it (an image's pixels are copied
    /// into shared memory, counted): kept and named, for a kept trajectory.
    fn encode(&mut self, sample: &Sample) {
        self.publish(&StoreEvent::Entered(sample.clone()));
        if let Some((_, owner)) = &self.own {
            let octets = sample.structure.attributes().any(|(_, v)| {
                v.as_bytes().is_some_and(|o| o.len() >= crate::client::holdings::HOLD_MIN_BYTES)
            });
            if octets {
                owner.count_sent(false);
            }
        }
        self.drain_own();
    }

    /// Takes what the own subscriber received, up to the sample `sequence`, and holds
    /// that one, read in place.
    fn receive_own(&mut self, sequence: u64) -> Option<SharedStructure> {
        let (own, owner) = self.own.as_ref()?;
        loop {
            match own.receive() {
                Ok(Some(sample)) if sample.header().sequence == sequence => {
                    return owner
                        .hold(sample)
                        .map_err(|e| {
                            tracing::warn!(error = %e, "cannot read back an image this process sent")
                        })
                        .ok();
                }
                Ok(Some(_)) => {}
                Ok(None) => {
                    tracing::warn!(trajectory = %self.publisher.trajectory(),
                        "an image this process sent did not come back; its store keeps the loan's view");
                    return None;
                }
                Err(e) => {
                    tracing::debug!(error = %e, "own subscriber");
                    return None;
                }
            }
        }
    }

    /// Drops what the own subscriber received (it reads only images sent from loans).
    fn drain_own(&mut self) {
        let Some((own, _)) = &self.own else { return };
        while let Ok(Some(_)) = own.receive() {}
    }

    fn failed(&mut self, e: &dyn std::fmt::Display) {
        self.failures += 1;
        if is_power_of_ten(self.failures) {
            tracing::warn!(trajectory = %self.publisher.trajectory(), error = %e,
                failures = self.failures,
                "cannot publish to other processes (the log says the 1st, 10th, 100th… only)");
        }
    }

    /// A structure this process admitted did not reach the other processes. Unless
    /// some got it ([`PublishError::NotDelivered`]: the others count it lost), its
    /// number is forgone, so readers see the gap, and the writer counts it
    /// ([`esgm_core::DropCause::Unpublished`], taken by the store after the entry).
    fn entry_failed(&mut self, e: &PublishError) {
        self.failed(e);
        if !matches!(e, PublishError::NotDelivered { .. }) {
            self.publisher.forgo();
            self.unpublished += 1;
        }
    }

    /// The violations publisher, opened now if this is the first violation.
    fn violation_publisher(&mut self) -> Result<&ViolationPublisher, PublishError> {
        if self.violations.is_none() {
            let ViolationSite { node, domain, trajectory, readers } = &self.violation_site;
            let opened =
                node.with(|node| ViolationPublisher::create(node, domain, trajectory, *readers));
            self.violations = Some(opened.map_err(|e| PublishError::Violations(Box::new(e)))?);
        }
        self.violations.as_ref().ok_or_else(|| {
            PublishError::Violations(Box::new(OpenError::from(
                crate::data_plane::service_name::NameError::Empty { what: "violations" },
            )))
        })
    }

    /// A structure that entered was not kept, for `why`: logged and counted. It is
    /// published in full instead: readers have it, it will not outlive this process.
    fn not_kept(&mut self, why: &dyn std::fmt::Display) {
        self.unkept += 1;
        if is_power_of_ten(self.unkept) {
            tracing::warn!(trajectory = %self.publisher.trajectory(), error = %why,
                not_kept = self.unkept,
                "a structure is not kept: it will not outlive this process (counted; \
                 the log says the 1st, 10th, 100th… only)");
        }
    }

    /// Publishes a structure in full (encoded into a loan, or an archive copied).
    fn publish_entry(&mut self, sample: &Sample) {
        let lineage = sample.lineage.as_deref();
        let sent =
            self.publisher.publish_produced(&sample.structure, sample.add_time, None, lineage);
        if let Err(e) = sent {
            self.entry_failed(&e);
        }
    }

    /// Keeps a structure that entered and publishes where it is, for a kept trajectory
    /// (written once, in the kept history); publishes it in full otherwise, or when it
    /// cannot be kept.
    fn keep_and_publish(&mut self, sample: &Sample) {
        if let Some(kept) = &mut self.kept {
            let lineage = sample.lineage.as_deref();
            match kept.write_traced(&sample.structure, sample.add_time, lineage) {
                Ok(at) => {
                    esgm_core::probe::mark(esgm_core::probe::Step::Kept);
                    let times = (sample.valid_time(), sample.create_time());
                    if let Err(e) = self.publisher.publish_kept(&at, times, sample.add_time) {
                        self.entry_failed(&e);
                    }
                    return;
                }
                Err(e) => self.not_kept(&e),
            }
        }
        self.publish_entry(sample);
    }

    /// Publishes again an entry the kept history holds at `at` (a writer that restarted
    /// or took over hands it on with the index readers know it by).
    fn publish_kept_again(&mut self, at: &KeptLocation, sample: &Sample) {
        let times = (sample.valid_time(), sample.create_time());
        if let Err(e) = self.publisher.publish_kept(at, times, sample.add_time) {
            self.entry_failed(&e);
        }
    }

    fn publish(&mut self, event: &StoreEvent) {
        let result = match event {
            StoreEvent::Entered(s) => {
                self.keep_and_publish(s);
                return;
            }
            StoreEvent::Violation(v) => self.violation_publisher().and_then(|p| p.publish(v)),
            StoreEvent::Reset => {
                if let Some(kept) = &mut self.kept {
                    kept.reset();
                }
                self.publisher.publish_reset().map(|_| ())
            }
            _ => Ok(()),
        };
        if let Err(e) = result {
            self.failed(&e);
        }
    }
}

/// How an export begins the stream it publishes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ExportStart {
    /// A trajectory made here, or a writer that restarted: its store holds nothing yet
    /// (what the trajectory kept enters it).
    New,
    /// A name re-pointed here (E5): a reset marker first, so readers elsewhere forget
    /// the stream the name denoted before.
    Repointed,
    /// A replica taken over from a writer that is gone: its store holds the history
    /// up to the kept index `known` (`None`: nothing kept), and the rest enters from
    /// the kept history.
    TakenOver {
        /// The highest kept index the replica entered.
        known: Option<u64>,
    },
}

impl ExportStart {
    /// The highest kept index the store holds already.
    fn known(self) -> Option<u64> {
        match self {
            ExportStart::TakenOver { known } => known,
            ExportStart::New | ExportStart::Repointed => None,
        }
    }
}

/// A local trajectory published for other processes.
#[derive(Debug)]
pub(crate) struct Export {
    /// The registry generation this export was built for.
    pub generation: u64,
    outlet: Arc<Mutex<Outlet>>,
    handle: InProcessTrajectory,
    tap: TapId,
    /// Primitive trajectories: other processes' adds and blocking adds.
    inbox: Option<Inbox>,
    /// The join service new readers ring for their history, for the receiver thread.
    join: EventSpec,
    /// The publisher's subscribers ([`TrajectoryPublisher::readers_fingerprint`]) when
    /// its connections were last updated.
    readers_seen: parking_lot::Mutex<Option<u128>>,
}

impl Drop for Export {
    fn drop(&mut self) {
        // The store outlives the export when the name is re-pointed or only this
        // process's bridge goes: stop publishing from it.
        let tap = self.tap;
        // A destroyed store has no tap to remove.
        let _destroyed = self.handle.with_store(|s| s.clear_tap(tap));
    }
}

impl Export {
    /// The id of the publisher port this export writes with (`UniquePublisherId`'s
    /// value), which the writer registers ([`crate::control::Request::ReportWriter`]).
    pub fn publisher(&self) -> u128 {
        self.outlet.lock().publisher.id().value()
    }

    /// Publishes `handle`'s stream (the trajectory of `record`) from now on (and its current content, so readers
    /// that connect later receive the history), as `start` says. `register`
    /// is given the publisher port's id once it is open and before anything is
    /// published on it (the writer names it to the registry there).
    ///
    /// A primitive trajectory's kept history is opened (made if new): what a former
    /// writer kept there and the store does not hold yet enters the store first, so a
    /// writer that restarted, or took over, continues the same history with no gap,
    /// and readers receive it again numbered as before (they skip what they hold).
    pub fn start(
        node: &SharedNode,
        domain: &str,
        handle: &InProcessTrajectory,
        record: &TrajectoryRecord,
        start: ExportStart,
        holdings: &Arc<Holdings>,
        register: &mut dyn FnMut(u128),
    ) -> Result<Self, ExportError> {
        let name = handle.name().to_owned();
        let (type_name, policy) = (&record.info.type_name, &record.info.policy);
        let primitive = record.info.kind == TrajectoryKind::Primitive;
        let generation = record.generation;
        // Lineage names the registry's generation, the same in every process.
        let _destroyed = handle.with_store(|s| s.set_generation(generation));
        let domain = &generation_domain(domain, generation);
        let readers = record.readers;
        let qos = handle_qos(handle, policy, readers);
        let images = has_octets(handle);
        // Only a destroyed trajectory has no type; without one each sample is sized.
        let fixed = handle.entity_type().ok().as_ref().and_then(fixed_sample_len);
        let (publisher, own) = node.with(|node| {
            let mut publisher =
                TrajectoryPublisher::builder(&name, type_name).domain(domain).qos(qos);
            if let Some(len) = fixed {
                publisher = publisher.sizing(SampleSizing::Fixed).max_len(len);
            }
            let publisher = publisher.create(node)?;
            let own = match images {
                true => Some(
                    TrajectorySubscriber::builder(&name, type_name)
                        .domain(domain)
                        .qos(qos)
                        // Read right after each send, never waited on.
                        .wait_strategy(WaitStrategy::BusySpin)
                        .create(node)?,
                ),
                false => None,
            };
            Ok::<_, ExportError>((publisher, own))
        })?;
        register(publisher.id().value());
        let inbox = match primitive {
            true => Some(Inbox {
                wake: EventSpec {
                    name: *TrajectoryServiceNames::new(&inbox_domain(domain), &name)
                        .map_err(OpenError::from)?
                        .wake(),
                    capacity: inbox_qos(readers).wake_capacity(),
                },
                node: node.clone(),
                domain: domain.to_owned(),
                type_name: type_name.to_owned(),
                readers,
                ports: Mutex::new(None),
                rejected: AtomicU64::new(0),
            }),
            false => None,
        };
        let join = EventSpec {
            name: join_service(domain, &name).map_err(OpenError::from)?,
            capacity: EventCapacity::to_writer(readers),
        };
        // One borrow stays free to receive into.
        let own = own.map(|o| (o, holdings.owner(qos.max_borrowed_samples.saturating_sub(1))));
        let violation_site = ViolationSite {
            node: node.clone(),
            domain: domain.to_owned(),
            trajectory: name.clone(),
            readers,
        };
        let kept = match primitive && !record.volatile {
            true => open_kept(domain, &name, type_name, policy),
            false => None,
        };
        let outlet = Arc::new(Mutex::new(Outlet {
            publisher,
            violations: None,
            violation_site,
            own,
            failures: 0,
            unpublished: 0,
            kept,
            unkept: 0,
        }));
        let owner = Arc::as_ptr(&outlet) as *const () as usize;
        // Content and tap under one lock: nothing falls between the two, and the
        // backlog is published before any later event.
        let tap = Arc::clone(&outlet);
        let tap = handle
            .with_store(|s| {
                let former = outlet.lock().kept.as_ref().map(KeptHistory::entries);
                let former = former.filter(|f| !f.entries.is_empty());
                if let Some(former) = &former {
                    for entry in &former.entries {
                        if start.known().is_none_or(|k| entry.index > k) {
                            let lineage = entry.lineage.clone().map(Arc::new);
                            s.replicate(entry.structure.clone(), entry.add_time, lineage);
                        }
                    }
                }
                let (id, backlog) =
                    s.set_tap(Box::new(OutletTap { outlet: tap, owner, unpublished: 0 }));
                if images {
                    s.set_octets_allocator(Arc::new(LoanAllocator::new(
                        &outlet,
                        Outlet::loan_image,
                    )));
                }
                let mut out = outlet.lock();
                if matches!(start, ExportStart::Repointed) {
                    out.publish(&StoreEvent::Reset);
                }
                match former {
                    // Handed on as kept, with the indices readers know it by, where it is.
                    Some(former) => {
                        for entry in former.entries {
                            let at = out.kept.as_ref().and_then(|k| k.location(entry.index));
                            let sample =
                                Sample::new(entry.structure, entry.add_time, entry.add_time)
                                    .with_lineage(entry.lineage.map(Arc::new));
                            match at {
                                Some(at) => out.publish_kept_again(&at, &sample),
                                None => out.publish_entry(&sample),
                            }
                        }
                    }
                    None => {
                        for sample in backlog {
                            out.publish(&StoreEvent::Entered(sample));
                        }
                    }
                }
                id
            })
            .map_err(|_| ExportError::Gone { trajectory: name.clone() })?;
        Ok(Self {
            generation,
            outlet,
            handle: handle.clone(),
            tap,
            inbox,
            join,
            readers_seen: parking_lot::Mutex::new(None),
        })
    }

    /// True for a primitive trajectory's export (other processes add to it).
    pub fn is_primitive(&self) -> bool {
        self.inbox.is_some()
    }

    /// The inbox's wake-up service (primitive trajectories), which adders ring.
    pub fn inbox_wake(&self) -> Option<EventSpec> {
        self.inbox.as_ref().map(|i| i.wake)
    }

    /// The join service new readers ring for their history.
    pub fn join_wake(&self) -> EventSpec {
        self.join
    }

    /// Hands readers that connected since the last send their history now and wakes
    /// them, so a reader that rang the join service answers its first query with the
    /// whole history, also on a trajectory nobody adds to any more.
    pub fn welcome(&self) {
        let outlet = self.outlet.lock();
        if let Err(e) = outlet.publisher.welcome() {
            tracing::debug!(trajectory = %outlet.publisher.trajectory(), error = %e,
                "cannot hand new readers their history");
        }
    }

    /// Hands readers that connected since the last send the history now, not only at
    /// the next sample.
    pub fn update_connections(&self) {
        let outlet = self.outlet.lock();
        // Connections change only when readers come or go: an idle trajectory costs a
        // look at its service's list of subscribers. (A reader made through `connect`
        // also rings the join service, which hands it its history at once; a bridge's
        // or a recorder's own subscriber is found here.)
        let readers = Some(outlet.publisher.readers_fingerprint());
        if std::mem::replace(&mut *self.readers_seen.lock(), readers) == readers {
            return;
        }
        if let Err(e) = outlet.publisher.update_connections() {
            tracing::debug!(trajectory = %outlet.publisher.trajectory(), error = %e,
                "cannot update the connections of a trajectory's publisher");
        }
    }

    /// Adds what other processes sent to the inbox through this process's gate;
    /// returns how many there were. Whatever the gate refuses is counted in the
    /// trajectory's stats (and published as a violation).
    ///
    /// The inbox's ports are opened the first time an adder rings: an idle primitive
    /// trajectory pays nothing for them (a subscriber and a server sized for every
    /// possible adder, about 0.7 MiB of private memory).
    ///
    /// `rung`: an adder rang the inbox (else this is a look for what may have come
    /// without a ring, which opens nothing).
    pub fn take_inbox(&self, rung: bool) -> usize {
        let Some(inbox) = &self.inbox else { return 0 };
        let mut ports = inbox.ports.lock();
        if ports.is_none() {
            if !rung {
                return 0;
            }
            match inbox.open(self.handle.name()) {
                Ok(opened) => *ports = Some(opened),
                Err(e) => {
                    tracing::warn!(trajectory = %self.handle.name(), error = %e,
                        "cannot open the inbox; other processes' adds wait");
                    return 0;
                }
            }
        }
        let Some((port, blocking)) = ports.as_ref() else { return 0 };
        let mut n = blocking.serve(&self.handle);
        loop {
            match port.receive() {
                Ok(Some(sample)) => {
                    n += 1;
                    // The add's archive, copied as it is (never decoded): the gate checks it
                    // in place, and a kept trajectory keeps its bytes as they came.
                    match SharedStructure::archived_copy(sample.archive_bytes()) {
                        Ok(es) => {
                            // The gate counts (and publishes) what it refuses.
                            if let Err(e) = self.handle.add_shared(es) {
                                tracing::debug!(trajectory = %self.handle.name(), error = %e,
                                    "add from another process refused");
                            }
                        }
                        Err(e) => inbox.reject(&self.handle, Rejection::Malformed, &e),
                    }
                }
                Ok(None) => break,
                Err(e) => match e.rejection() {
                    Some(why) => {
                        n += 1;
                        inbox.reject(&self.handle, why, &e);
                    }
                    // Adders never send resets or name kept entries (only a writer
                    // keeps): a marker or a name in the inbox is a kind of sample it
                    // does not take; the adds behind it are still taken.
                    None if matches!(
                        e,
                        ReceiveError::Reset { .. } | ReceiveError::KeptGone { .. }
                    ) =>
                    {
                        n += 1;
                        inbox.reject(&self.handle, Rejection::UnknownKind, &e);
                    }
                    None => {
                        tracing::debug!(trajectory = %self.handle.name(), error = %e,
                            "cannot receive from the inbox now");
                        break;
                    }
                },
            }
        }
        n
    }
}

/// A primitive trajectory's inbox: where other processes' adds arrive.
#[derive(Debug)]
struct Inbox {
    /// The wake-up service adders ring, which the receiver thread listens to.
    wake: EventSpec,
    node: SharedNode,
    /// The generation's domain.
    domain: String,
    type_name: String,
    readers: Readers,
    /// The subscriber of adds and the server of blocking adds, opened at the first
    /// ring.
    ports: Mutex<Option<(TrajectorySubscriber, AddServer)>>,
    /// Adds from other processes that were not samples of the trajectory.
    rejected: AtomicU64,
}

impl Inbox {
    /// Counts bytes another process put in the inbox that are not a sample of the
    /// trajectory, in its stats ([`esgm_core::DropCause::Rejected`]), as a replica counts
    /// what its writer sent. The log says the 1st, 10th, 100th… only: a hostile local
    /// process can fill the stats, not the log.
    fn reject(&self, handle: &InProcessTrajectory, why: Rejection, detail: &dyn std::fmt::Display) {
        let n = self.rejected.fetch_add(1, Ordering::Relaxed) + 1;
        if is_power_of_ten(n) {
            tracing::warn!(trajectory = %handle.name(), cause = %why, error = %detail, rejected = n,
                "an add from another process is not a sample of the trajectory (counted in its \
                 stats; the log says the 1st, 10th, 100th… only)");
        }
        // A trajectory destroyed meanwhile counts nothing.
        let _destroyed = handle.with_store(|s| s.replicate_rejection(why));
    }

    fn open(&self, trajectory: &str) -> Result<(TrajectorySubscriber, AddServer), ExportError> {
        self.node.with(|node| {
            let inbox = TrajectorySubscriber::builder(trajectory, &self.type_name)
                .domain(inbox_domain(&self.domain))
                .qos(inbox_qos(self.readers))
                // Nobody waits on it: the receiver thread does (see `receiver`).
                .wait_strategy(WaitStrategy::BusySpin)
                .create(node)?;
            let blocking = AddServer::open(node, &self.domain, trajectory, self.readers)?;
            Ok((inbox, blocking))
        })
    }
}

/// The store's tap: publishes each event through the shared outlet.
struct OutletTap {
    outlet: Arc<Mutex<Outlet>>,
    /// The outlet's identity, which its loans carry.
    owner: usize,
    /// Entries not published, taken from the outlet under the lock that published
    /// them: the store asks right after, and the outlet is not locked twice per entry.
    unpublished: u64,
}

impl esgm_core::StoreTap for OutletTap {
    fn observe(&mut self, event: &StoreEvent) {
        let mut outlet = self.outlet.lock();
        outlet.publish(event);
        self.unpublished += std::mem::take(&mut outlet.unpublished);
    }

    fn entering(&mut self, sample: &Sample) -> Option<SharedStructure> {
        let mut outlet = self.outlet.lock();
        let kept = outlet.enter(sample, self.owner);
        self.unpublished += std::mem::take(&mut outlet.unpublished);
        kept
    }

    fn take_unpublished(&mut self) -> u64 {
        std::mem::take(&mut self.unpublished)
    }
}

/// Opens the kept history of a primitive trajectory this process writes; `None`
/// (logged) if it cannot: the trajectory works, but its history lives only in this
/// process and its readers.
fn open_kept(
    domain: &str,
    trajectory: &str,
    type_name: &str,
    policy: &esgm_core::FluentStreamPolicy,
) -> Option<KeptHistory> {
    let retention = Retention::of(&policy.cache);
    KeptHistory::open_or_create(
        domain,
        trajectory,
        crate::data_plane::type_id::type_id(type_name),
        retention,
    )
    .map_err(|e| {
        tracing::warn!(trajectory, error = %e,
                "no kept history: the trajectory's history will not outlive this process")
    })
    .ok()
}

/// True if the trajectory's type has octet sequences (images).
fn has_octets(handle: &InProcessTrajectory) -> bool {
    handle
        .entity_type()
        .is_ok_and(|t| t.attributes.iter().any(|a| a.sort == esgm_core::value::ValueSort::OctetSeq))
}

/// True for 1, 10, 100…: how often a flood of the same failure is logged.
fn is_power_of_ten(mut n: u64) -> bool {
    while n >= 10 && n % 10 == 0 {
        n /= 10;
    }
    n == 1
}

#[cfg(test)]
mod tests {
    use super::is_power_of_ten;

    #[test]
    fn a_flood_is_logged_at_powers_of_ten() {
        let logged: Vec<u64> = (1..=1000).filter(|&n| is_power_of_ten(n)).collect();
        assert_eq!(logged, [1, 10, 100, 1000]);
        assert!(!is_power_of_ten(0));
    }
}
