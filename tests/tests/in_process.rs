//! The conformance suite on the in-process runtime.

esgm_tests::conformance_tests!(in_process, esgm_tests::InProcessHarness::new);

/// Dropping the runtime stops its workers (they hold their trajectory, not the
/// runtime, so nothing else would).
#[test]
fn dropping_the_runtime_stops_its_workers() {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicU64, Ordering};
    use std::time::Duration;

    use esgm_core::{
        EntityStructure, Esgm, InProcessEsgm, SensorError, SimClock, Time, millis, secs,
    };

    let clock = SimClock::shared(secs(1_000));
    let esgm = InProcessEsgm::builder().clock(clock.clone()).create();
    let calls = Arc::new(AtomicU64::new(0));
    let c = Arc::clone(&calls);
    let sensor = move |q: Time| -> Result<EntityStructure, SensorError> {
        c.fetch_add(1, Ordering::SeqCst);
        Ok(EntityStructure::new("r", q, q).with("x", 1.0).with("y", 2.0).with("dir", 3.0))
    };
    esgm.add_sensor_interface("s", "RobotState", Arc::new(sensor)).unwrap();
    esgm.create_entity_trajectory_structure("t", "s", 0, 0, millis(10), 0, 0).unwrap();
    assert!(esgm_tests::wait_for(Duration::from_secs(10), || calls.load(Ordering::SeqCst) == 1));
    drop(esgm);
    for _ in 0..5 {
        clock.advance(millis(10));
        std::thread::sleep(Duration::from_millis(30));
    }
    assert!(calls.load(Ordering::SeqCst) <= 2, "sampling went on after the runtime was dropped");
}
