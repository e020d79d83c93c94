//! One pipeline stage alone: a structure added in location `a` crosses to a unit in
//! location `b`, whose output crosses back to a subscriber in `a`. Prints the hop into
//! the unit (add in `a` → the unit is called in `b`) and the hop back (the unit is
//! called → the subscriber in `a` holds its output), to compare with one plain hop
//! (`examples/connect_hop.rs`): a stage that costs more than a hop in the tutorial
//! pipeline waits for something else (a busy core), not for esgm.
//!
//! Both locations and an in-process coordinator run in this process, so one clock
//! times everything; a structure every 2 ms.
//!
//! ```sh
//! cargo run --release -p esgm-shm --example unit_hop [-- <count>]
//! ```

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use esgm_core::esgm::{ComputeError, InputType, TrajectorySpec};
use esgm_core::{
    EntityStructure, EntityTrajectoryStructure, Esgm, Sample, SubscribeOptions, Time, TypeRegistry,
};
use esgm_shm::control::{Coordinator, Registry};
use esgm_shm::{ShmEsgm, unique_domain};

fn main() -> anyhow::Result<()> {
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
    let count: usize = std::env::args().nth(1).map_or(Ok(2000), |a| a.parse())?;
    let domain = unique_domain("unit-hop");
    let coordinator = Coordinator::spawn(&domain, Registry::new(TypeRegistry::with_library()))?;
    let location =
        |host: &str| ShmEsgm::builder().domain(coordinator.domain()).host(host).connect();
    let (a, b) = (location("a")?, location("b")?);
    let here = a.create_trajectory(TrajectorySpec::primitive("robot", "RobotState"))?;
    // The unit notes when it is called, and copies its input.
    let called: Arc<Mutex<Option<Instant>>> = Arc::default();
    let note = Arc::clone(&called);
    let unit = move |inputs: &[Sample], _q: Time| -> Result<EntityStructure, ComputeError> {
        if let Ok(mut at) = note.lock() {
            *at = Some(Instant::now());
        }
        let input = inputs.first().ok_or(ComputeError::ValueNotAvailable)?;
        Ok(input.structure.to_structure())
    };
    let input = vec![InputType::Type("RobotState".into())];
    b.add_comp_unit("copy", "RobotState", input, Arc::new(unit))?;
    let _copy = b.create_computed_entity_trajectory_structure("copied", "copy", &["robot"])?;
    let back = a.get_entity_trajectory_structure("copied")?;
    let sub = back.subscribe(SubscribeOptions::default())?;
    std::thread::sleep(Duration::from_millis(500));

    let (mut into, mut out) = (Vec::with_capacity(count), Vec::with_capacity(count));
    for i in 0..count as i64 {
        std::thread::sleep(Duration::from_millis(2));
        let es =
            EntityStructure::new("robot1", i, i).with("x", 1.0).with("y", 0.0).with("dir", 0.0);
        let start = Instant::now();
        here.add(es)?;
        while sub.recv_timeout(Duration::from_secs(5))?.structure.valid_time() != i {}
        let end = Instant::now();
        let at = called.lock().ok().and_then(|c| *c).context("the unit was not called")?;
        into.push(at - start);
        out.push(end - at);
    }
    into.sort();
    out.sort();
    let p = |v: &[Duration], q: f64| v[((v.len() - 1) as f64 * q) as usize];
    println!(
        "a -> unit in b: p50 {:?}, p99 {:?}; unit -> subscriber in a: p50 {:?}, p99 {:?}",
        p(&into, 0.5),
        p(&into, 0.99),
        p(&out, 0.5),
        p(&out, 0.99)
    );
    Ok(())
}
