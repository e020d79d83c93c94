//! `inproc-chain3`: the latency of a three-stage computed chain, against one hop.
//!
//! source → unit → unit → unit, on the in-process runtime: a primitive `RobotState`
//! trajectory and three computed trajectories, each fed by a trivial unit that copies
//! its input structure. The measuring thread adds to the source and waits (blocking)
//! on a subscription to the third stage, so the one-way time is timed directly, on
//! one thread. Units wait for their inputs by blocking (the runtime's only way), so the
//! row is an `event` one, compared with the blocking single hop of `inproc-hop-small`:
//! the difference is what the chain adds.

use std::hint::black_box;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context as _, bail};
use esgm_core::{
    AddOutcome, CacheConstraint, ComputeError, EntityStructure, EntityTrajectoryStructure, Esgm,
    FluentStreamPolicy, InProcessEsgm, InProcessTrajectory, InputType, Sample, SubscribeOptions,
    Time, TrajectorySpec,
};

use super::inproc_echo::Payload;
use super::inproc_hop_small::{self, Small};
use crate::inbox::receive;
use crate::latency::Latency;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};

/// The scenario's name.
pub const NAME: &str = "inproc-chain3";

const UNIT: &str = "bench-copy";
const SOURCE: &str = "bench-source";
const STAGES: [&str; 3] = ["bench-stage1", "bench-stage2", "bench-stage3"];

/// See the module docs.
#[derive(Debug, Clone, Copy, Default)]
pub struct InprocChain3;

impl Scenario for InprocChain3 {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "add to a source -> three computed trajectories (copying units) -> subscriber"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let samples = ctx.samples(100_000, 10_000);
        let warmup = ctx.warmup(samples);
        let esgm = InProcessEsgm::default();
        let workers = ctx.worker_pin();

        let pin = workers.clone();
        let copy =
            move |inputs: &[Sample], _qtime: Time| -> Result<EntityStructure, ComputeError> {
                pin.apply();
                inputs
                    .first()
                    .map(|s| s.structure.to_structure())
                    .ok_or(ComputeError::ValueNotAvailable)
            };
        let robot = || vec![InputType::Type(Small::TYPE_NAME.into())];
        esgm.add_comp_unit(UNIT, Small::TYPE_NAME, robot(), Arc::new(copy))
            .context("could not register the copying unit")?;

        let source = create(&esgm, TrajectorySpec::primitive(SOURCE, Small::TYPE_NAME))?;
        let mut input = SOURCE;
        let mut last = None;
        for stage in STAGES {
            last = Some(create(&esgm, TrajectorySpec::computed(stage, UNIT, [input]))?);
            input = stage;
        }
        let Some(last) = last else { bail!("the chain has no stage") };
        let output = last
            .subscribe(SubscribeOptions::default())
            .context("could not subscribe to the last stage")?;

        let mut latency = Latency::new()?;
        let mut payload = Small;
        for i in 0..warmup + samples {
            let es = Arc::new(payload.make(i));
            ctx.before_hop(Wait::Event);
            let start = Instant::now();
            match source.add_shared(es).context("add to the source failed")? {
                AddOutcome::Added => {}
                other => bail!("add to the source was not delivered: {other:?}"),
            }
            let out = receive(&output, Wait::Event, "output of the third stage")?;
            black_box(Small::touch(&out.structure));
            let one_way = start.elapsed();
            if i >= warmup {
                latency.record(one_way);
            }
        }
        workers.check()?;
        // Stop the unit workers now rather than when the runtime goes.
        for name in STAGES.iter().rev().chain([&SOURCE]) {
            esgm.destroy_entity_trajectory_structure(name)
                .with_context(|| format!("could not destroy {name}"))?;
        }

        Ok(vec![
            latency
                .measurement(NAME, Wait::Event)
                .payload_bytes(payload_bytes()?)
                .method(Method::OneWay)
                .baseline(inproc_hop_small::NAME)
                .note("units block on their inputs; vs baseline = what the chain adds to one hop"),
        ])
    }
}

/// A trajectory keeping only its latest structure.
fn create(esgm: &InProcessEsgm, mut spec: TrajectorySpec) -> anyhow::Result<InProcessTrajectory> {
    let name = spec.name.clone();
    spec.policy = FluentStreamPolicy::unconstrained().cache(CacheConstraint::Elements(1));
    esgm.create_trajectory(spec).with_context(|| format!("could not create {name}"))
}

fn payload_bytes() -> anyhow::Result<u64> {
    let size = esgm_core::codec::encoded_len(&Small.make(0))
        .context("could not measure the archived size of the payload")?;
    Ok(size as u64)
}
