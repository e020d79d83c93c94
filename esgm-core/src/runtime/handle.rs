//! The in-process trajectory handle.

use std::sync::Arc;

use super::cell::{Descriptor, TrajectoryCell};
use crate::approximation::ValueApproximation;
use crate::esgm::EntityTrajectoryStructure;
use crate::pixel_buffer::PixelBuffer;
use crate::policy::FluentStreamPolicy;
use crate::sample::Sample;
use crate::store::{
    AddError, AddOutcome, PolicyViolation, QueryError, SubscribeOptions, Subscription,
    SubscriptionId, TrajectoryStats, TrajectoryStore,
};
use crate::structure::SharedStructure;
use crate::time::Time;
use crate::types::EntityStructureType;
use crate::value::frame::{AttributeList, EntityStructure};

/// A handle on a trajectory of the in-process runtime: a proxy for its name.
#[derive(Debug, Clone)]
pub struct InProcessTrajectory {
    pub(crate) descriptor: Arc<Descriptor>,
}

impl InProcessTrajectory {
    fn cell(&self) -> Option<Arc<TrajectoryCell>> {
        self.descriptor.get()
    }

    fn gone_q(&self) -> QueryError {
        QueryError::NoSuchEntityStructure { trajectory: self.descriptor.name.clone() }
    }

    fn gone_a(&self) -> AddError {
        AddError::NoSuchEntityStructure { trajectory: self.descriptor.name.clone() }
    }

    /// Runs `f` on the current store, under its lock. `f` must not call back into the
    /// runtime for the same trajectory (that would wait for the lock it holds).
    pub fn with_store<R>(
        &self,
        f: impl FnOnce(&mut TrajectoryStore) -> R,
    ) -> Result<R, QueryError> {
        let cell = self.cell().ok_or_else(|| self.gone_q())?;
        let mut store = cell.store.lock();
        Ok(f(&mut store))
    }

    fn query<R>(
        &self,
        f: impl FnOnce(&TrajectoryStore) -> Result<R, QueryError>,
    ) -> Result<R, QueryError> {
        self.with_store(|s| f(s))?
    }

    /// [`EntityTrajectoryStructure::add`] of a structure made from others, named by
    /// `lineage`: what a bridge enters when it carries a produced structure from
    /// another host, with the inputs it was made from there.
    pub fn add_produced(
        &self,
        es: EntityStructure,
        lineage: Option<Arc<crate::lineage::Lineage>>,
    ) -> Result<AddOutcome, AddError> {
        self.add_with("add", |s| s.add_produced(Arc::new(es), lineage, false))
    }

    fn add_with(
        &self,
        operation: &'static str,
        f: impl FnOnce(&mut TrajectoryStore) -> Result<AddOutcome, AddError>,
    ) -> Result<AddOutcome, AddError> {
        let cell = self.cell().ok_or_else(|| self.gone_a())?;
        // A writer elsewhere that is gone: this process asks to take the trajectory
        // over first (outside the store's lock, which the transport needs to make
        // this store the writer's), so the add is served, never sent to nobody.
        let forwarder = cell.store.lock().add_forwarder();
        if let Some(f) = forwarder.filter(|f| f.writer_gone()) {
            f.take_over(&self.descriptor.name)?;
        }
        let mut store = cell.store.lock();
        if !cell.external_adds && !store.accepts_adds() {
            return Err(AddError::OperationNotSupported {
                trajectory: self.descriptor.name.clone(),
                operation: operation.into(),
            });
        }
        let outcome = f(&mut store);
        drop(store);
        if let Ok(AddOutcome::Held { .. }) = outcome {
            cell.kick_releaser();
        }
        outcome
    }

    /// A buffer for an image's pixels in this trajectory's own memory — its shared
    /// memory where the trajectory is published to other processes, so a frame added
    /// with these pixels (as its `image_data`) is never copied — else on the heap.
    /// `None` for an unknown format or an impossible size.
    pub fn image_buffer(&self, width: i64, height: i64, format: i64) -> Option<PixelBuffer> {
        // Only a destroyed trajectory has no store: its image goes on the heap.
        let own = self.with_store(|s| s.octets_allocator()).ok().flatten();
        own.and_then(|a| a.image(width, height, format))
            .or_else(|| PixelBuffer::heap_image(width, height, format))
    }

    /// Counts `n` messages a bridge to another middleware lost on their way into or
    /// out of this trajectory, so that `esgm stats` shows them with their cause
    /// (an importing bridge counts on the trajectory it writes, an exporting one on
    /// the replica it reads).
    pub fn count_bridge_loss(&self, loss: crate::BridgeLoss, n: u64) -> Result<(), QueryError> {
        self.with_store(|s| s.count_bridge_loss(loss, n))
    }

    /// Adds an already shared structure without copying it (zero-copy push): owned, or
    /// a sample's structure as received, archived in place.
    pub fn add_shared(&self, es: impl Into<SharedStructure>) -> Result<AddOutcome, AddError> {
        self.add_with("add", |s| s.add_shared(es, false))
    }
}

impl EntityTrajectoryStructure for InProcessTrajectory {
    fn name(&self) -> &str {
        &self.descriptor.name
    }
    fn entity_type(&self) -> Result<EntityStructureType, QueryError> {
        self.with_store(|s| s.entity_type().as_ref().clone())
    }
    fn policy(&self) -> Result<FluentStreamPolicy, QueryError> {
        self.with_store(|s| s.policy().clone())
    }
    fn start_time(&self) -> Result<Time, QueryError> {
        self.query(|s| s.start_time())
    }
    fn end_time(&self) -> Result<Time, QueryError> {
        self.query(|s| s.end_time())
    }
    fn get_latest(&self) -> Result<Sample, QueryError> {
        self.query(|s| s.get_latest())
    }
    fn get_latest_vtime(&self) -> Result<Sample, QueryError> {
        self.query(|s| s.get_latest_vtime())
    }
    fn get_nth_latest(&self, n: usize) -> Result<Sample, QueryError> {
        self.query(|s| s.get_nth_latest(n))
    }
    fn get_between(&self, from: Time, to: Time) -> Result<Vec<Sample>, QueryError> {
        self.with_store(|s| s.get_between(from, to))
    }
    fn get_closest_at_or_before(&self, t: Time) -> Result<Sample, QueryError> {
        self.query(|s| s.get_closest_at_or_before(t))
    }
    fn get_at(&self, t: Time) -> Result<Sample, QueryError> {
        self.query(|s| s.get_at(t))
    }
    fn get_at_approximating(
        &self,
        t: Time,
        aprx: &ValueApproximation,
    ) -> Result<Sample, QueryError> {
        self.query(|s| s.get_at_approximating(t, aprx))
    }
    fn subscribe(&self, options: SubscribeOptions) -> Result<Subscription<Sample>, QueryError> {
        self.with_store(|s| s.subscribe(options))
    }
    fn unsubscribe(&self, id: SubscriptionId) -> Result<(), QueryError> {
        self.with_store(|s| {
            s.unsubscribe(id);
        })
    }
    fn subscribe_violations(
        &self,
        capacity: usize,
    ) -> Result<Subscription<PolicyViolation>, QueryError> {
        self.with_store(|s| s.subscribe_violations(capacity))
    }
    fn add(&self, es: EntityStructure) -> Result<AddOutcome, AddError> {
        self.add_with("add", |s| s.add(es))
    }
    fn add_blocking(&self, es: EntityStructure) -> Result<AddOutcome, AddError> {
        self.add_with("add_blocking", |s| s.add_blocking(es))
    }
    fn create_at(
        &self,
        name: &str,
        valid_time: Time,
        attributes: AttributeList,
    ) -> Result<AddOutcome, AddError> {
        self.add_with("create_at", |s| s.create_at(name, valid_time, attributes))
    }
    fn create_at_blocking(
        &self,
        name: &str,
        valid_time: Time,
        attributes: AttributeList,
    ) -> Result<AddOutcome, AddError> {
        self.add_with("create_at_blocking", |s| s.create_at_blocking(name, valid_time, attributes))
    }
    fn create_at_now(&self, name: &str, attributes: AttributeList) -> Result<AddOutcome, AddError> {
        self.add_with("create_at_now", |s| s.create_at_now(name, attributes))
    }
    fn create_at_now_blocking(
        &self,
        name: &str,
        attributes: AttributeList,
    ) -> Result<AddOutcome, AddError> {
        self.add_with("create_at_now_blocking", |s| s.create_at_now_blocking(name, attributes))
    }
    fn reset(&self) -> Result<(), QueryError> {
        match self.with_store(|s| s.reset_forwarder())? {
            Some(forwarder) => forwarder.reset(self.name(), false),
            None => self.with_store(|s| s.reset()),
        }
    }
    fn reset_blocking(&self) -> Result<(), QueryError> {
        match self.with_store(|s| s.reset_forwarder())? {
            Some(forwarder) => forwarder.reset(self.name(), true),
            None => self.with_store(|s| s.reset_blocking()),
        }
    }
    fn stats(&self) -> Result<TrajectoryStats, QueryError> {
        self.with_store(|s| s.stats())
    }
}
