//! The threads that feed sampled, computed and operator trajectories.
//!
//! Every call into user code (sensors, units) is isolated with `catch_unwind`: a
//! panicking unit is counted and logged, and its trajectory keeps running.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use crossbeam_channel::Receiver;

use super::cell::{Descriptor, TrajectoryCell, Worker, WorkerCounters};
use super::{inputs, periodic};
use crate::clock::SharedClock;
use crate::esgm::{CallOutcome, CompUnit, ComputeError, SensorError, SensorInterface};
use crate::generator::GeneratorPolicy;
use crate::lineage::{InputRef, Lineage};
use crate::operators::sync::{InputDrops, MEMBER_CREATE_TIMES, MEMBER_VALID_TIMES, SyncPolicy};
use crate::pixel_buffer::{HeapAllocator, OctetsAllocator};
use crate::sample::Sample;
use crate::store::{AddError, AddOutcome, FanIn};
use crate::structure::SharedStructure;
use crate::time::Time;
use crate::value::Value;
use crate::value::frame::{AttributeValuePair, EntityStructure};

/// Starts `body` on a named thread and returns the handle that stops it.
pub(crate) fn spawn(
    kind: &str,
    cell: &Arc<TrajectoryCell>,
    body: impl FnOnce(Arc<AtomicBool>, Receiver<()>) + Send + 'static,
) -> Worker {
    let stop = Arc::new(AtomicBool::new(false));
    let (wake_tx, wake_rx) = crossbeam_channel::bounded::<()>(0);
    let thread_stop = Arc::clone(&stop);
    let name = format!("esgm-{kind}-{}", cell.info.name);
    if let Err(e) = std::thread::Builder::new().name(name).spawn(move || body(thread_stop, wake_rx))
    {
        tracing::error!(trajectory = %cell.info.name, error = %e, "could not start worker thread");
    }
    Worker { stop, _wake: Some(wake_tx) }
}

/// Runs user code, counting a panic instead of propagating it.
fn guarded<R>(cell: &TrajectoryCell, what: &str, f: impl FnOnce() -> R) -> Option<R> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => Some(r),
        Err(payload) => {
            WorkerCounters::bump(&cell.counters.panics);
            let msg = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "non-string panic".into());
            tracing::error!(trajectory = %cell.info.name, %what, panic = %msg, "user code panicked; isolated");
            cell.counters.called(now(cell), CallOutcome::Panicked(msg));
            None
        }
    }
}

/// Adds a produced structure to the worker's own trajectory, with the inputs it was
/// made from (none for a sensor's).
fn emit(cell: &TrajectoryCell, es: impl Into<SharedStructure>, lineage: Option<Lineage>) {
    WorkerCounters::bump(&cell.counters.outputs);
    let (result, at) = {
        let mut store = cell.store.lock();
        (store.add_produced(es, lineage.map(Arc::new), false), store.clock().now())
    };
    let outcome = match result {
        Ok(AddOutcome::Held { .. }) => {
            cell.kick_releaser();
            CallOutcome::Produced
        }
        Ok(AddOutcome::Dropped(v)) => {
            CallOutcome::Dropped(format!("{}: {}", v.constraint, v.detail))
        }
        Ok(_) => CallOutcome::Produced,
        Err(AddError::InvalidType { source, .. }) => {
            WorkerCounters::bump(&cell.counters.invalid_outputs);
            tracing::warn!(trajectory = %cell.info.name, error = %source, "worker output has the wrong type");
            CallOutcome::InvalidOutput(source.to_string())
        }
        Err(e) => {
            WorkerCounters::bump(&cell.counters.failures);
            tracing::warn!(trajectory = %cell.info.name, error = %e, "worker output refused");
            CallOutcome::Failed(e.to_string())
        }
    };
    cell.counters.called(at, outcome);
}

/// The trajectory's clock, now.
fn now(cell: &TrajectoryCell) -> Time {
    cell.store.lock().clock().now()
}

fn missed(cell: &TrajectoryCell) -> impl FnMut(crate::esgm::MissedPoints) + '_ {
    move |points| {
        let n = points.missed;
        cell.counters.missed_periods.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
        cell.counters.missed(points);
    }
}

/// A sampled trajectory: calls the sensor at every sample time.
pub(crate) fn sampler(
    cell: &Arc<TrajectoryCell>,
    clock: SharedClock,
    sensor: Arc<dyn SensorInterface>,
    schedule: periodic::Schedule,
) -> Worker {
    let c = Arc::clone(cell);
    spawn("sampler", cell, move |stop, _wake| {
        let call_ended = std::cell::Cell::new(None);
        periodic::run(&clock, &stop, schedule, &call_ended, missed(&c), |qtime| {
            WorkerCounters::bump(&c.counters.calls);
            // The trajectory's own image buffers (shared memory where it is published).
            let images = c.store.lock().octets_allocator();
            let images: &dyn OctetsAllocator = match &images {
                Some(a) => a.as_ref(),
                None => &HeapAllocator,
            };
            let value =
                guarded(&c, "get_current_value", || sensor.get_current_value_with(qtime, images));
            call_ended.set(Some(clock.now()));
            match value {
                Some(Ok(es)) => emit(&c, Arc::new(es), None),
                Some(Err(SensorError::ValueNotAvailable)) => {
                    WorkerCounters::bump(&c.counters.no_value);
                    c.counters.called(now(&c), CallOutcome::NoValue);
                }
                Some(Err(e)) => {
                    WorkerCounters::bump(&c.counters.failures);
                    tracing::warn!(trajectory = %c.info.name, error = %e, "sensor failed");
                    c.counters.called(now(&c), CallOutcome::Failed(e.to_string()));
                }
                None => {}
            }
        });
    })
}

/// What a worker remembers of one input: its latest sample, and the input's reset count
/// when that sample arrived (a reset of the input makes the sample forgotten: after a
/// reset the input has no latest sample until it gets a new one), and how to name the
/// input's structures in an output's lineage.
#[derive(Debug)]
pub(crate) struct InputState {
    latest: Option<Sample>,
    seen_resets: u64,
    resets: Arc<std::sync::atomic::AtomicU64>,
    trajectory: String,
    generation: Arc<std::sync::atomic::AtomicU64>,
}

impl InputState {
    pub(crate) fn new(
        latest: Option<Sample>,
        store: &crate::store::TrajectoryStore,
        trajectory: &str,
    ) -> Self {
        let resets = store.reset_counter();
        let seen_resets = resets.load(std::sync::atomic::Ordering::Relaxed);
        let generation = store.generation();
        Self { latest, seen_resets, resets, trajectory: trajectory.to_owned(), generation }
    }

    /// Names `sample`, read from this input, in an output's lineage.
    fn input_ref(&self, sample: &Sample) -> InputRef {
        InputRef {
            trajectory: self.trajectory.clone(),
            generation: self.generation.load(std::sync::atomic::Ordering::Relaxed),
            valid_time: sample.valid_time(),
            add_time: sample.add_time,
        }
    }

    /// True (and forgets the latest sample) if the input was reset since it was seen.
    fn forget_if_reset(&mut self) -> bool {
        let now = self.resets.load(std::sync::atomic::Ordering::Relaxed);
        if now != self.seen_resets {
            self.seen_resets = now;
            self.latest = None;
            return true;
        }
        false
    }
}

/// Forgets what was reset, then records `sample` as input `i`'s latest; true if any
/// input had been reset.
fn update_inputs(states: &mut [InputState], i: usize, sample: Sample) -> bool {
    let mut any_reset = false;
    for s in states.iter_mut() {
        any_reset |= s.forget_if_reset();
    }
    if let Some(s) = states.get_mut(i) {
        s.latest = Some(sample);
    }
    any_reset
}

/// A computed trajectory: on every input update, calls the unit with the latest sample
/// of each input, once every input has one.
pub(crate) fn unit(
    cell: &Arc<TrajectoryCell>,
    clock: SharedClock,
    cu: Arc<dyn CompUnit>,
    fan_in: FanIn<Sample>,
    mut states: Vec<InputState>,
) -> Worker {
    let c = Arc::clone(cell);
    spawn("unit", cell, move |stop, wake| {
        // The inputs handed to each call, in one buffer for the worker's life: a call
        // allocates nothing for them.
        let mut args: Vec<Sample> = Vec::with_capacity(states.len());
        inputs::run(
            fan_in,
            wake,
            &stop,
            &c.counters.input_overflow,
            &c.counters.flush_done,
            |i, sample| {
                let added = sample.add_time;
                crate::probe::mark(crate::probe::Step::Taken);
                update_inputs(&mut states, i, sample);
                args.clear();
                args.extend(states.iter().map_while(|s| s.latest.clone()));
                if args.len() < states.len() {
                    crate::probe::settle(added);
                    return;
                }
                WorkerCounters::bump(&c.counters.calls);
                let qtime = clock.now();
                let lineage = || {
                    let inputs = states.iter().zip(&args).map(|(s, a)| s.input_ref(a)).collect();
                    Lineage::of(inputs).with_unrecorded_reads()
                };
                crate::probe::mark(crate::probe::Step::Computed);
                crate::probe::settle(added);
                let result = guarded(&c, "compute", || cu.compute(&args, qtime));
                emit_computed(&c, "unit", result, lineage);
            },
        );
    })
}

/// Emits what a unit computed, counting an answer of "no value" and a failure (logged
/// as `what` failed); `None` is a panic `guarded` already counted.
fn emit_computed(
    cell: &TrajectoryCell,
    what: &str,
    result: Option<Result<EntityStructure, ComputeError>>,
    lineage: impl FnOnce() -> Lineage,
) {
    match result {
        Some(Ok(es)) => emit(cell, Arc::new(es), Some(lineage())),
        Some(Err(ComputeError::ValueNotAvailable)) => {
            WorkerCounters::bump(&cell.counters.no_value);
            cell.counters.called(now(cell), CallOutcome::NoValue);
        }
        Some(Err(e)) => {
            WorkerCounters::bump(&cell.counters.failures);
            tracing::warn!(trajectory = %cell.info.name, error = %e, "{what} failed");
            cell.counters.called(now(cell), CallOutcome::Failed(e.to_string()));
        }
        None => {}
    }
}

/// A state: one frame per input, named after the input trajectory.
pub(crate) fn state(
    name: &str,
    valid_time: Time,
    create_time: Time,
    parts: &[(&str, &SharedStructure)],
) -> EntityStructure {
    EntityStructure {
        name: name.to_owned(),
        valid_time,
        create_time,
        attributes: parts
            .iter()
            .map(|(input, es)| AttributeValuePair {
                name: (*input).to_owned(),
                // A state holds its members' values: each is converted into it (octet
                // sequences stay shared).
                value: Value::EntityFrame(Box::new(es.to_frame())),
            })
            .collect(),
    }
}

/// A synchronized trajectory (G2): states of samples matched by the synchronizer. A
/// state is valid at the latest valid time among its samples.
pub(crate) fn sync(
    cell: &Arc<TrajectoryCell>,
    clock: SharedClock,
    policy: SyncPolicy,
    names: Vec<String>,
    fan_in: FanIn<Sample>,
    mut states: Vec<InputState>,
) -> Worker {
    let c = Arc::clone(cell);
    spawn("sync", cell, move |stop, wake| {
        let Ok(mut synchronizer) = policy.create::<Sample>(names.len()) else { return };
        let mut discarded = 0;
        // What former synchronizers (before a reset) discarded, per input.
        let mut former = vec![InputDrops::default(); names.len()];
        inputs::run(
            fan_in,
            wake,
            &stop,
            &c.counters.input_overflow,
            &c.counters.flush_done,
            |i, sample| {
                WorkerCounters::bump(&c.counters.calls);
                // A reset input's queued samples belong to a stream that no longer exists:
                // start matching afresh (what was queued counts as discarded).
                if states.iter_mut().fold(false, |any, s| s.forget_if_reset() | any) {
                    c.counters.discarded.fetch_add(
                        synchronizer.queued() as u64,
                        std::sync::atomic::Ordering::Relaxed,
                    );
                    for (input, drops) in former.iter_mut().enumerate() {
                        drops.merge(
                            synchronizer.drops().get(input).unwrap_or(&InputDrops::default()),
                        );
                        drops.reset += synchronizer.queued_on(input) as u64;
                    }
                    *c.counters.sync_drops.lock() = former.clone();
                    if let Ok(fresh) = policy.create::<Sample>(names.len()) {
                        synchronizer = fresh;
                        discarded = 0;
                    }
                }
                let result = synchronizer.push(i, sample);
                // Samples the synchronizer gave up on are counted, never lost silently,
                // and by input and reason for `why`.
                let now_discarded = synchronizer.dropped();
                if now_discarded != discarded {
                    c.counters
                        .discarded
                        .fetch_add(now_discarded - discarded, std::sync::atomic::Ordering::Relaxed);
                    discarded = now_discarded;
                    let mut drops = former.clone();
                    for (sum, now) in drops.iter_mut().zip(synchronizer.drops()) {
                        sum.merge(now);
                    }
                    *c.counters.sync_drops.lock() = drops;
                }
                match result {
                    Ok(sets) => {
                        for set in sets {
                            let vt = set.iter().map(|s| s.valid_time()).max().unwrap_or_default();
                            let parts: Vec<(&str, &SharedStructure)> = names
                                .iter()
                                .map(String::as_str)
                                .zip(set.iter().map(|s| &s.structure))
                                .collect();
                            let mut es = state(&c.info.name, vt, clock.now(), &parts);
                            // Which samples were matched (documented in `operators::sync`).
                            let times = |f: fn(&Sample) -> Time| set.iter().map(f).collect();
                            es.attributes.push(AttributeValuePair {
                                name: MEMBER_VALID_TIMES.to_owned(),
                                value: Value::LongSeq(times(|s| s.structure.valid_time())),
                            });
                            es.attributes.push(AttributeValuePair {
                                name: MEMBER_CREATE_TIMES.to_owned(),
                                value: Value::LongSeq(times(|s| s.structure.create_time())),
                            });
                            let inputs =
                                states.iter().zip(&set).map(|(s, a)| s.input_ref(a)).collect();
                            emit(&c, es, Some(Lineage::of(inputs)));
                        }
                    }
                    Err(e) => {
                        WorkerCounters::bump(&c.counters.failures);
                        tracing::warn!(trajectory = %c.info.name, error = %e, "sync failed");
                    }
                }
            },
        );
    })
}

/// A merged trajectory (G3): every sample of every input, shared, not copied.
pub(crate) fn merge(
    cell: &Arc<TrajectoryCell>,
    fan_in: FanIn<Sample>,
    states: Vec<InputState>,
) -> Worker {
    let c = Arc::clone(cell);
    spawn("merge", cell, move |stop, wake| {
        inputs::run(
            fan_in,
            wake,
            &stop,
            &c.counters.input_overflow,
            &c.counters.flush_done,
            |i, sample| {
                WorkerCounters::bump(&c.counters.calls);
                let from = states.get(i).map(|s| Lineage::of(vec![s.input_ref(&sample)]));
                emit(&c, sample.structure, from);
            },
        );
    })
}

/// A trajectory sampled from generators (G4): at each sample time, each input's
/// generator value at `t`, `lag` before it; one input gives its value re-stamped at
/// `t`, several give a state.
pub(crate) fn sampled_generators(
    cell: &Arc<TrajectoryCell>,
    clock: SharedClock,
    inputs: Vec<(Arc<Descriptor>, GeneratorPolicy)>,
    cu: Option<Arc<dyn CompUnit>>,
    schedule: periodic::Schedule,
    lag: Time,
) -> Worker {
    let c = Arc::clone(cell);
    spawn("generator", cell, move |stop, _wake| {
        let call_ended = std::cell::Cell::new(None);
        periodic::run(&clock, &stop, schedule, &call_ended, missed(&c), |sample_time| {
            let t = sample_time.saturating_sub(lag);
            WorkerCounters::bump(&c.counters.calls);
            let mut values = Vec::with_capacity(inputs.len());
            let mut from = Vec::with_capacity(inputs.len());
            for (d, policy) in &inputs {
                let Some(input) = d.get() else {
                    WorkerCounters::bump(&c.counters.failures);
                    return;
                };
                let store = input.store.lock();
                let generation = store.generation().load(std::sync::atomic::Ordering::Relaxed);
                let value = store.generator(policy).value_at_from(t);
                drop(store);
                match value {
                    Ok((s, sources)) => {
                        values.push(s);
                        from.extend(sources.into_iter().map(|(valid_time, add_time)| InputRef {
                            trajectory: d.name.clone(),
                            generation,
                            valid_time,
                            add_time,
                        }));
                    }
                    // Every `value_at` error means no value at `t`: counted as such.
                    Err(_) => {
                        WorkerCounters::bump(&c.counters.no_value);
                        return;
                    }
                }
            }
            if let Some(cu) = &cu {
                // A temporal function: the unit estimates the value at exactly `t`.
                let result = guarded(&c, "compute_at", || cu.compute_at(&values, t));
                call_ended.set(Some(clock.now()));
                emit_computed(&c, "compute_at", result, || {
                    Lineage::of(from).with_unrecorded_reads()
                });
                return;
            }
            let es = match values.as_slice() {
                // One input's value re-stamped at `t`: a new structure of its fields.
                [one] => {
                    let mut es = one.structure.to_structure();
                    es.valid_time = t;
                    es
                }
                many => {
                    let parts: Vec<(&str, &SharedStructure)> = inputs
                        .iter()
                        .map(|(d, _)| d.name.as_str())
                        .zip(many.iter().map(|s| &s.structure))
                        .collect();
                    state(&c.info.name, t, clock.now(), &parts)
                }
            };
            call_ended.set(Some(clock.now()));
            emit(&c, es, Some(Lineage::of(from)));
        });
    })
}
