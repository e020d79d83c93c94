//! Names, handles and the whole-ESGM operations (E5–E7), asked of both sides: names
//! and registrations are system-wide, so the reader gets the same answers and errors
//! as the writer, and sees what the writer's destroys and re-points do to the stream.

use std::sync::Arc;

use esgm_core::{
    AddError, ComputeError, CreateError, EntityStructure, EntityTrajectoryStructure, Esgm,
    LookupError, QueryError, RegistrationError, Sample, SensorError, SubscribeOptions, Time,
    TrajectorySpec, esgm::LogLevel, millis,
};

use super::{WAIT, read, reading, register_reading, wait_stored, wait_visible, x_of};
use crate::{Harness, wait_for};

/// A unit that copies its one input.
fn copy(i: &[Sample], _: Time) -> Result<EntityStructure, ComputeError> {
    Ok(i[0].structure.to_structure())
}

/// Unknown names get the seed's errors, with a suggestion when one is close, on
/// either side.
pub fn unknown_names_get_the_seed_errors<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    e.create_primitive_entity_trajectory_structure("blobs", "Reading").unwrap();
    for side in [e, h.reader()] {
        assert!(side.get_entity_trajectory_structure("blobs").is_ok());
        let err = side.get_entity_trajectory_structure("blobz").unwrap_err();
        assert_eq!(
            err.to_string(),
            "no entity trajectory structure `blobz`; did you mean `blobs`?"
        );
        assert!(matches!(
            side.destroy_entity_trajectory_structure("nope"),
            Err(LookupError::NoSuchEntityStructure { .. })
        ));
        assert!(matches!(
            side.create_primitive_entity_trajectory_structure("x", "Readin"),
            Err(CreateError::NoSuchEntityStructureType { suggestion: Some(_), .. })
        ));
        assert!(matches!(
            side.create_entity_trajectory_structure("x", "camera", 0, 0, millis(10), 0, 0),
            Err(CreateError::NoSuchSensor { .. })
        ));
        assert!(matches!(
            side.create_primitive_entity_trajectory_structure("blobs", "Reading"),
            Err(CreateError::EntityStructureAlreadyExists { .. })
        ));
        assert!(matches!(
            side.remove_sensor_interface("cam"),
            Err(RegistrationError::NoSuchSensor { .. })
        ));
        assert!(matches!(
            side.remove_comp_unit("cu"),
            Err(RegistrationError::NoSuchCompUnit { .. })
        ));
        let s = Arc::new(|q: Time| -> Result<EntityStructure, SensorError> { Ok(reading(q, 0.0)) });
        assert!(matches!(
            side.add_sensor_interface("cam", "Nope", s),
            Err(RegistrationError::NoSuchEntityStructureType { .. })
        ));
    }
    let s = Arc::new(|q: Time| -> Result<EntityStructure, SensorError> { Ok(reading(q, 0.0)) });
    e.add_sensor_interface("cam", "Reading", s.clone()).unwrap();
    assert!(matches!(
        e.add_sensor_interface("cam", "Reading", s),
        Err(RegistrationError::SensorAlreadyExists { .. })
    ));
}

/// E6: a sensor or unit name is registered once, system-wide: registering it again
/// — from the other side or from the same one — is refused, and the refusal leaves
/// the first registration in place for everyone (its trajectories can still be made).
pub fn duplicate_registrations_are_refused<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let s = Arc::new(|q: Time| -> Result<EntityStructure, SensorError> { Ok(reading(q, 0.0)) });
    e.add_sensor_interface("cam", "Reading", s.clone()).unwrap();
    e.add_comp_unit("copy", "Reading", vec!["Reading".into()], Arc::new(copy)).unwrap();
    for side in [h.reader(), e] {
        let again = side.add_sensor_interface("cam", "Reading", s.clone());
        assert!(matches!(again, Err(RegistrationError::SensorAlreadyExists { .. })), "{again:?}");
        let again = side.add_comp_unit("copy", "Reading", vec!["Reading".into()], Arc::new(copy));
        assert!(matches!(again, Err(RegistrationError::CompUnitAlreadyExists { .. })), "{again:?}");
    }
    for side in [e, h.reader()] {
        assert_eq!(side.sensors().unwrap(), vec![("cam".to_owned(), "Reading".to_owned())]);
        assert_eq!(side.comp_units().unwrap().len(), 1);
    }
    e.create_entity_trajectory_structure("s", "cam", 0, 0, millis(100), 0, 0).unwrap();
    e.create_computed_entity_trajectory_structure("c", "copy", &["s"]).unwrap();
    let (sampled, c) = (read(h, "s"), read(h, "c"));
    // The sampler's first tick may come before the unit is attached (then it computes
    // from the next one) or after (then from both).
    wait_stored(&sampled, 1);
    h.advance(millis(100));
    assert!(wait_for(WAIT, || c.get_latest().is_ok()), "the unit never computed");
}

/// E5: a destroyed name can be reused; the destroyer's old handles report the
/// trajectory is gone (the writer's own outcome; [`destroyed_names_are_gone_for_readers`]
/// is the reader's side).
pub fn destroy_and_reuse_a_name<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let old = e.create_primitive_entity_trajectory_structure("r", "Reading").unwrap();
    old.add(reading(h.now(), 1.0)).unwrap();
    e.destroy_entity_trajectory_structure("r").unwrap();
    assert!(matches!(old.get_latest(), Err(QueryError::NoSuchEntityStructure { .. })));
    assert!(matches!(old.add(reading(h.now(), 1.0)), Err(AddError::NoSuchEntityStructure { .. })));
    let new = e.create_primitive_entity_trajectory_structure("r", "Image").unwrap();
    assert_eq!(new.entity_type().unwrap().name, "Image");
    assert!(
        e.get_entity_trajectory_structure("r").unwrap().get_latest().is_err(),
        "fresh and empty"
    );
}

/// E5 across locations: when the writer destroys a trajectory, the reader's handles
/// report it gone (queries and adds), the name is unknown to the reader, and once
/// the name is reused the reader reaches the new trajectory, fresh and of its type.
pub fn destroyed_names_are_gone_for_readers<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let old = e.create_primitive_entity_trajectory_structure("r", "Reading").unwrap();
    let seen = read(h, "r");
    old.add(reading(h.now(), 1.0)).unwrap();
    wait_visible(&old, &seen);
    e.destroy_entity_trajectory_structure("r").unwrap();
    let gone = || matches!(seen.get_latest(), Err(QueryError::NoSuchEntityStructure { .. }));
    assert!(wait_for(WAIT, gone), "the reader's handle still answers: {:?}", seen.get_latest());
    assert!(matches!(seen.add(reading(h.now(), 1.0)), Err(AddError::NoSuchEntityStructure { .. })));
    assert!(matches!(
        h.reader().get_entity_trajectory_structure("r"),
        Err(LookupError::NoSuchEntityStructure { .. })
    ));
    let new = e.create_primitive_entity_trajectory_structure("r", "Image").unwrap();
    let fresh = read(h, "r");
    assert_eq!(fresh.entity_type().unwrap().name, "Image");
    assert_eq!(h.reader().get_entity_trajectory_structure_type("r").unwrap().name, "Image");
    wait_visible(&new, &fresh);
    assert!(fresh.get_latest().is_err(), "fresh and empty for the reader");
}

/// E5 from the other side: the reader destroys a trajectory the writer writes; it is
/// gone for both, and the name can be created again.
pub fn destroy_through_the_reader<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let w = e.create_primitive_entity_trajectory_structure("r", "Reading").unwrap();
    let seen = read(h, "r");
    w.add(reading(h.now(), 1.0)).unwrap();
    wait_visible(&w, &seen);
    h.reader().destroy_entity_trajectory_structure("r").unwrap();
    assert!(matches!(seen.get_latest(), Err(QueryError::NoSuchEntityStructure { .. })));
    let gone = || matches!(w.get_latest(), Err(QueryError::NoSuchEntityStructure { .. }));
    assert!(wait_for(WAIT, gone), "the writer's handle still answers: {:?}", w.get_latest());
    assert!(matches!(
        e.get_entity_trajectory_structure("r"),
        Err(LookupError::NoSuchEntityStructure { .. })
    ));
    let again = e.create_primitive_entity_trajectory_structure("r", "Reading").unwrap();
    assert!(again.get_latest().is_err(), "fresh and empty");
    again.add(reading(h.now(), 2.0)).unwrap();
    let fresh = read(h, "r");
    wait_visible(&again, &fresh);
    assert_eq!(x_of(&fresh.get_latest().unwrap()), Some(2.0));
}

/// E5: re-pointing a name keeps its subscribers (they see the new stream from then
/// on) and its handles — a reader's too; a computed trajectory reading the name
/// follows it.
pub fn re_pointing_keeps_subscribers_and_handles<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    e.add_comp_unit("copy", "Reading", vec!["Reading".into()], Arc::new(copy)).unwrap();
    let handle = e.create_primitive_entity_trajectory_structure("r", "Reading").unwrap();
    e.create_computed_entity_trajectory_structure("d", "copy", &["r"]).unwrap();
    let seen = read(h, "r");
    let downstream = read(h, "d");
    let sub = seen.subscribe(SubscribeOptions::default()).unwrap();
    let t0 = h.now();
    handle.add(reading(t0, 1.0)).unwrap();
    wait_visible(&handle, &seen);
    e.create_trajectory(TrajectorySpec::primitive("r", "Reading").replace()).unwrap();
    assert!(handle.get_latest().is_err(), "the handle now reaches the new, empty trajectory");
    // The reader had the old stream's sample; an empty replica is the re-point arriving.
    wait_visible(&handle, &seen);
    assert!(seen.get_latest().is_err(), "the reader's handle reaches the new one too");
    handle.add(reading(t0 + 1, 2.0)).unwrap();
    let got: Vec<_> = (0..2).map(|_| sub.recv_timeout(WAIT).map(|s| x_of(&s))).collect();
    assert_eq!(got, vec![Ok(Some(1.0)), Ok(Some(2.0))]);
    wait_visible(&handle, &seen);
    wait_stored(&downstream, 2);
    // Re-pointing may not change the type (readers were checked against it) nor make
    // the name read itself, whoever asks.
    for side in [e, h.reader()] {
        assert!(matches!(
            side.create_trajectory(TrajectorySpec::primitive("r", "Image").replace()),
            Err(CreateError::TypeChange { .. })
        ));
        let looped = side.create_trajectory(TrajectorySpec::computed("r", "copy", ["d"]).replace());
        assert!(matches!(looped, Err(CreateError::Cycle { .. })), "{looped:?}");
    }
}

/// T4: only primitive trajectories take structures from outside, on either side.
pub fn external_adds_only_on_primitive<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let s = Arc::new(|q: Time| -> Result<EntityStructure, SensorError> { Ok(reading(q, 0.0)) });
    e.add_sensor_interface("cam", "Reading", s).unwrap();
    e.add_comp_unit("copy", "Reading", vec!["Reading".into()], Arc::new(copy)).unwrap();
    let t = e.create_entity_trajectory_structure("s", "cam", 0, 0, millis(100), 0, 0).unwrap();
    e.create_computed_entity_trajectory_structure("c", "copy", &["s"]).unwrap();
    assert!(matches!(t.add(reading(h.now(), 1.0)), Err(AddError::OperationNotSupported { .. })));
    for name in ["s", "c"] {
        let seen = read(h, name);
        let out = seen.add(reading(h.now(), 1.0));
        assert!(matches!(out, Err(AddError::OperationNotSupported { .. })), "{name}: {out:?}");
        let out = seen.create_at_now("r", reading(0, 1.0).attributes.into());
        assert!(matches!(out, Err(AddError::OperationNotSupported { .. })), "{name}: {out:?}");
    }
}

/// E6: a sensor or unit in use cannot be removed, whoever asks; once its users are
/// gone it can.
pub fn in_use_sensors_and_units_cannot_be_removed<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let s = Arc::new(|q: Time| -> Result<EntityStructure, SensorError> { Ok(reading(q, 0.0)) });
    e.add_sensor_interface("cam", "Reading", s).unwrap();
    e.add_comp_unit("copy", "Reading", vec!["Reading".into()], Arc::new(copy)).unwrap();
    e.create_entity_trajectory_structure("s", "cam", 0, 0, millis(100), 0, 0).unwrap();
    e.create_computed_entity_trajectory_structure("c", "copy", &["s"]).unwrap();
    for side in [e, h.reader()] {
        let err = side.remove_sensor_interface("cam").unwrap_err();
        assert_eq!(err.to_string(), "`cam` is used by s");
        let err = side.remove_comp_unit("copy").unwrap_err();
        assert!(matches!(err, RegistrationError::InUse { .. }), "{err}");
        assert_eq!(side.sensors().unwrap().len(), 1);
        assert_eq!(side.comp_units().unwrap().len(), 1);
    }
    e.destroy_entity_trajectory_structure("c").unwrap();
    e.remove_comp_unit("copy").unwrap();
    e.destroy_entity_trajectory_structure("s").unwrap();
    e.remove_sensor_interface("cam").unwrap();
    for side in [e, h.reader()] {
        assert!(side.sensors().unwrap().is_empty());
        assert!(side.comp_units().unwrap().is_empty());
    }
}

/// E7: stats, memory stats, ping, reset, log level, asked of either side: memory adds
/// up every process's, statistics are each trajectory's writer's, a reset of the
/// system empties what every process holds, the log level is set everywhere.
pub fn stats_memory_ping_reset_log_level<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let t = e.create_primitive_entity_trajectory_structure("r", "Reading").unwrap();
    let img = e.create_primitive_entity_trajectory_structure("img", "Image").unwrap();
    let (t_seen, img_seen) = (read(h, "r"), read(h, "img"));
    for k in 0..10 {
        t.add(reading(h.now() + k, k as f64)).unwrap();
    }
    let pixels = esgm_core::Octets::from(vec![0u8; 64 * 1024]);
    let image =
        esgm_core::library::Image { width: 128, height: 128, format: 1, image_data: pixels };
    use esgm_core::Entity;
    // The same image twice: counted once in memory.
    img.add(image.to_structure("i", h.now(), h.now())).unwrap();
    img.add(image.to_structure("i", h.now() + 1, h.now())).unwrap();
    assert!(e.ping());
    assert_eq!(e.stats().unwrap().trajectories["r"].stats.added, 10);
    // The reader: everything arrived, and its statistics say so.
    wait_visible(&t, &t_seen);
    wait_visible(&img, &img_seen);
    // Memory is the system's: every process holding the two trajectories (the writer,
    // and the reader's replicas where it is another process) counts what it holds,
    // an image once per process.
    let m = e.memory_stats().unwrap();
    let holders = m.trajectories / 2;
    assert!(holders >= 1 && m.trajectories == 2 * holders, "{m:?}");
    assert_eq!(m.stored_samples, 12 * holders);
    let pixels = 64 * 1024;
    assert!(m.approx_bytes >= pixels * holders && m.approx_bytes < 2 * pixels * holders, "{m:?}");
    assert!(h.reader().ping());
    assert_eq!(t_seen.stats().unwrap().added, 10);
    assert_eq!(h.reader().stats().unwrap().trajectories["r"].stats.added, 10);
    assert_eq!(h.reader().memory_stats().unwrap().stored_samples, 12 * holders);
    e.reset().unwrap();
    assert_eq!(e.memory_stats().unwrap().stored_samples, 0);
    wait_visible(&t, &t_seen);
    wait_visible(&img, &img_seen);
    assert_eq!(h.reader().memory_stats().unwrap().stored_samples, 0);
    e.set_log_level(LogLevel::Debug).unwrap();
    assert_eq!(e.log_level(), LogLevel::Debug);
    for side in [e, h.reader()] {
        assert_eq!(side.trajectories().unwrap().len(), 2);
    }
}
