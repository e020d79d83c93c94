//! One hop between two locations through `esgm_shm::connect`: a structure added to a
//! primitive trajectory in location `a` until a subscriber in location `b` holds it.
//!
//! Both locations (each with its own location thread and iceoryx2 node, as two
//! processes would have) and an in-process coordinator run in this process, so that
//! one clock times the hop. Structures are added one at a time with a pause between
//! them, as a sensor at a modest rate would: each finds `b` idle.
//!
//! Release build, this 2-core VM (24 November 2026): p50 43 µs, p99 113 µs (it was
//! 0.25–0.30 ms while a sample crossed four thread hand-offs). The cross-process
//! figures are `esgm-bench`'s `connect-small` (BENCHMARKS.md).
//!
//! ```sh
//! cargo run --release -p esgm-shm --example connect_hop [-- <count> <pause-ms>]
//! ```

use std::time::{Duration, Instant};

use esgm_core::esgm::TrajectorySpec;
use esgm_core::{EntityStructure, EntityTrajectoryStructure, Esgm, SubscribeOptions, TypeRegistry};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::{ShmEsgm, unique_domain};

fn main() -> anyhow::Result<()> {
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let mut args = std::env::args().skip(1);
    let count: usize = args.next().map_or(Ok(500), |a| a.parse())?;
    let pause = Duration::from_millis(args.next().map_or(Ok(5), |a| a.parse())?);

    let domain = unique_domain("connect-hop");
    let coordinator = Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library()))?;
    let location =
        |host: &str| ShmEsgm::builder().domain(coordinator.domain()).host(host).connect();
    let (a, b) = (location("a")?, location("b")?);
    let here = a.create_trajectory(TrajectorySpec::primitive("robot", "RobotState"))?;
    let there = b.get_entity_trajectory_structure("robot")?;
    let sub = there.subscribe(SubscribeOptions::default())?;

    let mut hops = Vec::with_capacity(count);
    for i in 0..count as i64 {
        std::thread::sleep(pause);
        let es =
            EntityStructure::new("robot1", i, i).with("x", 1.0).with("y", 0.0).with("dir", 0.0);
        let start = Instant::now();
        here.add(es)?;
        let got = sub.recv_timeout(Duration::from_secs(5))?;
        hops.push(start.elapsed());
        anyhow::ensure!(got.structure.valid_time() == i, "sample {i} arrived out of turn");
    }
    hops.sort();
    let at = |q: f64| hops[((hops.len() - 1) as f64 * q) as usize];
    println!(
        "connect hop a -> b, {count} structures, {} ms apart: p50 {:?}, p90 {:?}, p99 {:?}, max {:?}",
        pause.as_millis(),
        at(0.5),
        at(0.9),
        at(0.99),
        at(1.0)
    );
    Ok(())
}
