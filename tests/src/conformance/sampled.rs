//! Sampled trajectories (E3, E6 sensors): periods, from/to, failures. The sensor and
//! its sampler live with the writer; the samples are read through the reader.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use esgm_core::{
    Constraint, CreateError, DropCause, EntityStructure, EntityTrajectoryStructure, Esgm,
    SensorError, SensorInterface, Time, millis,
};

use super::{WAIT, read, reading, register_reading, wait_stored, wait_visible, x_of};
use crate::{Harness, wait_for};

/// A sensor whose value is valid at the query time and counts its calls.
fn counting_sensor() -> (Arc<AtomicU64>, Arc<dyn SensorInterface>) {
    let calls = Arc::new(AtomicU64::new(0));
    let c = Arc::clone(&calls);
    let sensor = move |qtime: Time| -> Result<EntityStructure, SensorError> {
        let n = c.fetch_add(1, Ordering::SeqCst);
        Ok(reading(qtime, n as f64))
    };
    (calls, Arc::new(sensor))
}

fn valid_times<T: EntityTrajectoryStructure>(t: &T) -> Vec<Time> {
    t.get_between(Time::MIN, Time::MAX).unwrap().iter().map(|s| s.valid_time()).collect()
}

/// E3: samples at from, from + period, … up to to, nothing after; the seed's 0 rules.
pub fn sampling_periods_and_from_to<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let (calls, sensor) = counting_sensor();
    e.add_sensor_interface("cam", "Reading", sensor).unwrap();
    let t0 = h.now();
    let p = millis(100);
    let w = e.create_entity_trajectory_structure("s", "cam", t0 + p, t0 + 3 * p, p, 0, 0).unwrap();
    let t = read(h, "s");
    // The reader's count waits for the writer's sampler too: a sample reaches the
    // reader only once sampled.
    h.advance(p);
    wait_stored(&t, 1);
    h.advance(p);
    wait_stored(&t, 2);
    h.advance(p);
    wait_stored(&t, 3);
    h.advance(p);
    h.advance(p);
    // Past `to` the sensor is not asked again (give a wrongly running sampler time to
    // show itself).
    assert!(!wait_for(std::time::Duration::from_millis(200), || calls.load(Ordering::SeqCst) > 3));
    wait_visible(&w, &t);
    assert_eq!(valid_times(&t), vec![t0 + p, t0 + 2 * p, t0 + 3 * p]);
    assert_eq!(t.stats().unwrap().dropped_total, 0);
    // from = 0: starts now; illegal policies are refused, whoever asks.
    e.create_entity_trajectory_structure("now", "cam", 0, 0, p, 0, 0).unwrap();
    let now = read(h, "now");
    wait_stored(&now, 1);
    assert_eq!(valid_times(&now), vec![h.now()]);
    for side in [e, h.reader()] {
        for (period, cache) in [(0, 0), (-1, 0), (p, -1)] {
            let r = side.create_entity_trajectory_structure("bad", "cam", 0, 0, period, 0, cache);
            assert!(
                matches!(r, Err(CreateError::IllegalPolicy(_))),
                "period {period} cache {cache}"
            );
        }
    }
}

/// E3: many trajectories with different periods on one sensor.
pub fn one_sensor_many_periods<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let (calls, sensor) = counting_sensor();
    e.add_sensor_interface("cam", "Reading", sensor).unwrap();
    let t0 = h.now();
    e.create_entity_trajectory_structure("fast", "cam", t0, 0, millis(100), 0, 0).unwrap();
    e.create_entity_trajectory_structure("slow", "cam", t0, 0, millis(300), 0, 0).unwrap();
    let (fast, slow) = (read(h, "fast"), read(h, "slow"));
    wait_stored(&fast, 1);
    wait_stored(&slow, 1);
    for k in 1..=6 {
        h.advance(millis(100));
        wait_stored(&fast, k + 1);
        wait_stored(&slow, k / 3 + 1);
    }
    assert_eq!(valid_times(&slow), vec![t0, t0 + millis(300), t0 + millis(600)]);
    let fast_times: Vec<Time> = (0..=6).map(|k| t0 + k * millis(100)).collect();
    assert_eq!(valid_times(&fast), fast_times);
    assert_eq!(calls.load(Ordering::SeqCst), 7 + 3);
}

/// A sensor that errors or panics is counted (by the sampler, with the writer);
/// sampling goes on, and the reader sees the samples it produced.
pub fn sensor_errors_and_panics_are_counted<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let n = Arc::new(AtomicU64::new(0));
    let c = Arc::clone(&n);
    let flaky = move |qtime: Time| -> Result<EntityStructure, SensorError> {
        match c.fetch_add(1, Ordering::SeqCst) {
            1 => Err(SensorError::Failed { reason: "bus error".into() }),
            2 => panic!("driver crashed"),
            3 => Err(SensorError::ValueNotAvailable),
            k => Ok(reading(qtime, k as f64)),
        }
    };
    e.add_sensor_interface("flaky", "Reading", Arc::new(flaky)).unwrap();
    let w = e.create_entity_trajectory_structure("f", "flaky", 0, 0, millis(10), 0, 0).unwrap();
    let t = read(h, "f");
    wait_stored(&t, 1);
    for k in 1..=4 {
        h.advance(millis(10));
        assert!(wait_for(WAIT, || n.load(Ordering::SeqCst) > k), "sampler stopped at call {k}");
    }
    wait_stored(&t, 2);
    wait_visible(&w, &t);
    let xs: Vec<_> = t.get_between(Time::MIN, Time::MAX).unwrap().iter().map(|s| x_of(s)).collect();
    assert_eq!(xs, vec![Some(0.0), Some(4.0)]);
    let w = e.stats().unwrap().trajectories["f"].worker;
    assert_eq!((w.calls, w.failures, w.panics, w.no_value, w.outputs), (5, 1, 1, 1, 2));
    assert!(e.ping());
    assert!(h.reader().ping());
}

/// C6 on a sampled trajectory: a value older than the allowed delay is a counted
/// violation (the sensor answered with a stale reading), reported to the reader.
pub fn late_sensor_is_a_delay_violation<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let stale = |qtime: Time| -> Result<EntityStructure, SensorError> {
        Ok(reading(qtime - millis(500), 1.0))
    };
    e.add_sensor_interface("stale", "Reading", Arc::new(stale)).unwrap();
    // Start the window in the past so the stale valid time is inside the duration.
    let from = h.now() - millis(1_000);
    let w = e
        .create_entity_trajectory_structure("s", "stale", from, 0, millis(100), millis(200), 0)
        .unwrap();
    let t = read(h, "s");
    let violations = t.subscribe_violations(16).unwrap();
    let delayed = |t: &<H::E as Esgm>::Trajectory| {
        matches!(t.stats().map(|s| s.dropped_for(DropCause::Violation(Constraint::Delay))),
            Ok(n) if n >= 1)
    };
    assert!(wait_for(WAIT, || delayed(&w)), "a late sample must be counted by the writer");
    // The reader joined before the first tick; the next tick is reported to it, if the
    // first was not.
    h.advance(millis(100));
    let v = violations.recv_timeout(WAIT).unwrap();
    assert_eq!(v.constraint, Constraint::Delay);
    assert!(wait_for(WAIT, || delayed(&t)), "a late sample must be counted as a delay violation");
    assert_eq!(w.stats().unwrap().added, 0);
    assert_eq!(t.stats().unwrap().added, 0);
}

/// The tutorial's images trajectory: sampled with a cache of 5.
pub fn sampled_cache_keeps_the_last_n<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let (_, sensor) = counting_sensor();
    e.add_sensor_interface("cam", "Reading", sensor).unwrap();
    let t0 = h.now();
    let w =
        e.create_entity_trajectory_structure("images", "cam", t0, 0, millis(1_000), 0, 5).unwrap();
    let t = read(h, "images");
    wait_stored(&t, 1);
    for k in 1..8 {
        h.advance(millis(1_000));
        assert!(wait_for(WAIT, || t.stats().map(|s| s.added) == Ok(k + 1)), "sample {k}");
    }
    wait_visible(&w, &t);
    let vts = valid_times(&t);
    assert_eq!(vts.len(), 5);
    assert_eq!(vts[0], t0 + millis(3_000));
    assert_eq!(t.stats().unwrap().evicted, 3, "the oldest went first");
}
