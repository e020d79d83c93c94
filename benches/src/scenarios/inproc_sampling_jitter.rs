//! `inproc-sampling-jitter`: how late a 100 Hz sampled trajectory samples.
//!
//! A sampled trajectory (E3) pulls a `RobotState` from a sensor closure every 10 ms;
//! the sensor stamps each structure valid at the scheduled sample time it is asked
//! for. Jitter is the add time the store recorded minus that scheduled time, read per
//! sample from a subscription (the same quantity as the trajectory's add-delay
//! statistics, at full resolution). The sampler sleeps between samples, so the row is
//! an `event` one; `--samples N` runs for N periods.

use std::sync::Arc;

use anyhow::Context as _;
use esgm_core::library::RobotState;
use esgm_core::{
    Entity, EntityStructure, EntityTrajectoryStructure, Esgm, InProcessEsgm, SensorError,
    SubscribeOptions, Time, millis,
};

use crate::inbox::receive;
use crate::latency::Latency;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};
use crate::table::duration;

/// The scenario's name.
pub const NAME: &str = "inproc-sampling-jitter";

/// 100 Hz.
const PERIOD: Time = millis(10);
/// Samples skipped at the start, while the sampler thread settles.
const WARMUP: u64 = 5;
const SENSOR: &str = "bench-sensor";
const TRAJECTORY: &str = "bench-sampled";

/// See the module docs.
#[derive(Debug, Clone, Copy, Default)]
pub struct InprocSamplingJitter;

impl Scenario for InprocSamplingJitter {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "100 Hz sampled trajectory: add time - scheduled sample time"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        let samples = ctx.samples(3_000, 500);
        let esgm = InProcessEsgm::default();
        let workers = ctx.worker_pin();

        let pin = workers.clone();
        let sensor = move |qtime: Time| -> Result<EntityStructure, SensorError> {
            pin.apply();
            Ok(RobotState { x: 1.0, y: 2.0, dir: 90.0 }.to_structure("robot", qtime, qtime))
        };
        esgm.add_sensor_interface(SENSOR, "RobotState", Arc::new(sensor))
            .context("could not register the sensor")?;
        let sampled = esgm
            .create_entity_trajectory_structure(TRAJECTORY, SENSOR, 0, 0, PERIOD, 0, 16)
            .context("could not create the sampled trajectory")?;
        let subscription =
            sampled.subscribe(SubscribeOptions::default()).context("could not subscribe")?;

        let mut jitter = Latency::new()?;
        let mut payload_bytes = 0;
        for i in 0..WARMUP + samples {
            let sample = receive(&subscription, Wait::Event, "sample")?;
            if i == 0 {
                payload_bytes = sample
                    .structure
                    .to_codec_bytes()
                    .map(|b| b.len())
                    .context("could not measure the archived size of the payload")?;
            }
            if i >= WARMUP {
                jitter.record_ns(u64::try_from(sample.add_time - sample.valid_time()).unwrap_or(0));
            }
        }
        let stats = sampled.stats().context("could not read the trajectory's stats")?;
        esgm.destroy_entity_trajectory_structure(TRAJECTORY)
            .context("could not stop the sampled trajectory")?;
        workers.check()?;

        let own =
            |t: Option<Time>| t.map_or("-".into(), |t| duration(u64::try_from(t).unwrap_or(0)));
        Ok(vec![
            jitter
                .measurement(NAME, Wait::Event)
                .payload_bytes(payload_bytes as u64)
                .method(Method::Lateness)
                .note(format!(
                    "period 10 ms; missed sample times {}; esgm's own add-delay stats: p50 {}, p99 {}, max {}",
                    stats.missed_sample_points,
                    own(stats.add_delay_p50),
                    own(stats.add_delay_p99),
                    own(stats.add_delay_max),
                )),
        ])
    }
}
