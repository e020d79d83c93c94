//! `inproc-hop-small`: one hop of a small structure through the in-process runtime.
//!
//! A `RobotState` (three doubles; about 100 bytes archived) added to a primitive
//! trajectory and delivered to a subscriber on another thread, with a busy-spinning
//! (`try_recv`) and a blocking (`recv`) subscriber. Measured as half a round trip
//! through two trajectories (see [`super::inproc_echo`]) against the raw crossbeam
//! floor.

use esgm_core::library::RobotState;
use esgm_core::{Clock, Entity, EntityStructure, SystemClock};

use super::inproc_echo::{Payload, ping_pong};
use super::inproc_floor_crossbeam;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};

/// The scenario's name.
pub const NAME: &str = "inproc-hop-small";

/// See the module docs.
#[derive(Debug, Clone, Copy, Default)]
pub struct InprocHopSmall;

impl Scenario for InprocHopSmall {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "add of a ~100-byte RobotState to a primitive trajectory -> subscriber thread"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        Wait::BOTH
            .iter()
            .map(|&wait| {
                let run = ping_pong(ctx, wait, Small)?;
                let mut m = run
                    .one_way
                    .measurement(NAME, wait)
                    .payload_bytes(run.payload_bytes)
                    .method(Method::HalfRoundTrip)
                    .baseline(inproc_floor_crossbeam::NAME);
                if !run.shared {
                    m = m.note("the structure came back as a different allocation: it was copied");
                }
                Ok(m)
            })
            .collect()
    }
}

/// Robot states valid now, each a little different.
#[derive(Debug, Clone, Copy, Default)]
pub struct Small;

impl Payload for Small {
    const TYPE_NAME: &'static str = "RobotState";

    fn make(&mut self, i: u64) -> EntityStructure {
        let now = SystemClock.now();
        let f = i as f64;
        RobotState { x: f, y: 0.5 * f, dir: 90.0 }.to_structure("robot", now, now)
    }

    fn touch(es: &esgm_core::SharedStructure) -> u64 {
        es.get("x").and_then(|v| v.as_double()).map_or(0, f64::to_bits)
    }
}
