//! The CPU a connected process uses while nothing happens: a writer connection with
//! three trajectories (one of images) and a reader connection mirroring them, with a
//! subscription and a unit waiting on them, idle for a while. Prints the share of one
//! core the process used (user + system time over wall time, from `/proc/self/stat`).
//!
//! ```sh
//! cargo run --release -p esgm-shm --example idle_cost [-- <seconds>]
//! ```

use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use esgm_core::esgm::{ComputeError, InputType, TrajectorySpec};
use esgm_core::{EntityStructure, EntityTrajectoryStructure, Esgm, Sample, SubscribeOptions, Time};
use esgm_core::{FluentStreamPolicy, TypeRegistry};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::{ShmEsgm, unique_domain};

/// CPU seconds used by this process's threads (user + system), all of them and those
/// of the in-process coordinator, from `/proc/self/task/*/stat`.
fn cpu_seconds() -> anyhow::Result<(f64, f64)> {
    let (mut all, mut coordinator) = (0.0, 0.0);
    for task in std::fs::read_dir("/proc/self/task")? {
        let stat = std::fs::read_to_string(task?.path().join("stat"))?;
        // The thread's name is in parentheses (and may hold spaces); fields follow.
        let (head, rest) = stat.rsplit_once(')').context("malformed task stat")?;
        let fields: Vec<&str> = rest.split_whitespace().collect();
        let ticks = |i: usize| -> anyhow::Result<f64> {
            Ok(fields.get(i).context("short task stat")?.parse::<f64>()?)
        };
        // utime and stime are fields 14 and 15 of the line: 11 and 12 after ')';
        // USER_HZ is 100 on Linux.
        let seconds = (ticks(11)? + ticks(12)?) / 100.0;
        all += seconds;
        if head.contains("esgm-coordinato") {
            coordinator += seconds;
        }
    }
    Ok((all, coordinator))
}

fn main() -> anyhow::Result<()> {
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let seconds: u64 = std::env::args().nth(1).map_or(Ok(20), |a| a.parse())?;
    let domain = unique_domain("idle-cost");
    let coordinator = Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library()))?;
    let connect = |host: &str| ShmEsgm::builder().domain(coordinator.domain()).host(host).connect();
    let (writer, reader) = (connect("writer")?, connect("reader")?);
    let cache = FluentStreamPolicy::default().cache(esgm_core::CacheConstraint::Elements(4));
    for (name, type_name) in [("a", "RobotState"), ("b", "RobotState"), ("frames", "Image")] {
        writer
            .create_trajectory(TrajectorySpec::primitive(name, type_name).policy(cache.clone()))?;
    }
    let unit = |inputs: &[Sample], _q: Time| -> Result<EntityStructure, ComputeError> {
        Ok(inputs[0].structure.to_structure())
    };
    let input = vec![InputType::Type("RobotState".into())];
    reader.add_comp_unit("copy", "RobotState", input, Arc::new(unit))?;
    let _copy = reader.create_computed_entity_trajectory_structure("copy_a", "copy", &["a"])?;
    let b = reader.get_entity_trajectory_structure("b")?;
    let _frames = reader.get_entity_trajectory_structure("frames")?;
    let sub = b.subscribe(SubscribeOptions::default())?;
    let waiter = std::thread::spawn(move || {
        let deadline = Instant::now() + Duration::from_secs(seconds + 2);
        while Instant::now() < deadline {
            let _nothing = sub.recv_timeout(Duration::from_secs(1));
        }
    });
    std::thread::sleep(Duration::from_secs(2)); // settled
    let (before, t0) = (cpu_seconds()?, Instant::now());
    std::thread::sleep(Duration::from_secs(seconds));
    let (after, wall) = (cpu_seconds()?, t0.elapsed().as_secs_f64());
    let (all, coordinator) = (after.0 - before.0, after.1 - before.1);
    let share = |cpu: f64| 100.0 * cpu / wall;
    println!(
        "idle for {wall:.1} s: the process {:.3} % of a core; the coordinator {:.3} %; \
         each connection (its threads, a waiting subscription or unit) {:.3} %",
        share(all),
        share(coordinator),
        share((all - coordinator) / 2.0)
    );
    if waiter.join().is_err() {
        anyhow::bail!("the waiting subscriber panicked");
    }
    Ok(())
}
