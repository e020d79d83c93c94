//! `control-ping` and `control-ping-churn` (issue 24): what a churn of short-lived
//! clients costs everybody else's calls to the coordinator. A churn once stalled the
//! next ping for 1.8 s (iceoryx2 initialised a large list per connecting client on the
//! coordinator's thread); `esgm-shm/tests/coordinator_probes.rs` tests the property
//! (another client is served while clients churn) by the order of events, and this
//! measures the stall in time.
//!
//! A coordinator runs on a thread of the measuring process. One steady client pings it
//! again and again, each call timed: alone (`control-ping`, the baseline), then while
//! another thread connects a client, pings with it and drops it, over and over
//! (`control-ping-churn`, with how many clients the churn made meanwhile in its note).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use esgm_core::TypeRegistry;
use esgm_shm::control::{ControlClient, Coordinator, Registry, Request, Response};
use esgm_shm::unique_domain;

use crate::latency::Latency;
use crate::report::{Measurement, Method, Wait};
use crate::scenario::{Context, Scenario};
use crate::target::Target;

/// The scenario's name.
pub const NAME: &str = "control-ping";
/// The row measured while clients churn.
pub const CHURN: &str = "control-ping-churn";
/// How long a client waits for the coordinator.
const DEADLINE: Duration = Duration::from_secs(10);

/// Both rows (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct ControlChurn;

impl Scenario for ControlChurn {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        "rows control-ping, control-ping-churn: a steady client's ping to the coordinator, alone and while other clients connect and leave"
    }

    fn run(&self, ctx: &Context) -> anyhow::Result<Vec<Measurement>> {
        iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
        let domain = unique_domain("esgm-bench-churn");
        let coordinator = Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library()))
            .with_context(|| format!("could not start a coordinator for {domain}"))?;
        let d = coordinator.domain().to_owned();
        let steady = ControlClient::connect(&d, DEADLINE).context("the steady client")?;
        let samples = ctx.samples(2_000, 100);
        let warmup = ctx.warmup(samples);
        let alone = pings(&steady, samples, warmup)?;

        let churned = Arc::new(AtomicU64::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let churn = {
            let (d, churned, stop) = (d.clone(), Arc::clone(&churned), Arc::clone(&stop));
            std::thread::spawn(move || -> anyhow::Result<()> {
                while !stop.load(Ordering::Acquire) {
                    let c = ControlClient::connect(&d, DEADLINE).context("a churned client")?;
                    ping(&c)?;
                    drop(c);
                    churned.fetch_add(1, Ordering::AcqRel);
                }
                Ok(())
            })
        };
        // The churn under way before the first measured ping.
        let deadline = Instant::now() + DEADLINE;
        while churned.load(Ordering::Acquire) == 0 {
            if Instant::now() > deadline || churn.is_finished() {
                stop.store(true, Ordering::Release);
                bail!("the churn's first client was not answered within {DEADLINE:?}");
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        let from = churned.load(Ordering::Acquire);
        let during = pings(&steady, samples, warmup);
        let made = churned.load(Ordering::Acquire) - from;
        stop.store(true, Ordering::Release);
        churn.join().map_err(|_| anyhow::anyhow!("the churn thread panicked"))??;
        let during = during?;
        drop(steady);
        drop(coordinator);
        let row = |latency: &Latency, name: &str| {
            latency.measurement(name, Wait::Event).method(Method::Call).wait_strategy("block")
        };
        Ok(vec![
            row(&alone, NAME).note("one client's ping to the coordinator, nobody else connected"),
            row(&during, CHURN).baseline(NAME).note(format!(
                "the same ping while another thread connected, pinged and dropped {made} clients"
            )),
        ])
    }

    /// A churn costs the others at most a few of its calls' worth, never a stall: the
    /// steady client's p50 within ×3 of its ping alone.
    fn targets(&self) -> Vec<Target> {
        vec![Target::at_most(CHURN, NAME, Wait::Event, 3.0)]
    }
}

/// `samples` timed pings after `warmup` untimed ones.
fn pings(client: &ControlClient, samples: u64, warmup: u64) -> anyhow::Result<Latency> {
    let mut latency = Latency::new()?;
    for i in 0..warmup + samples {
        let started = Instant::now();
        ping(client)?;
        if i >= warmup {
            latency.record_ns(u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX));
        }
    }
    Ok(latency)
}

/// One ping, answered with a pong.
fn ping(client: &ControlClient) -> anyhow::Result<()> {
    match client.call(&Request::Ping).context("a ping")? {
        Response::Pong { .. } => Ok(()),
        other => bail!("a ping was answered with {other:?}"),
    }
}
