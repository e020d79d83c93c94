//! Names, handles and the whole-ESGM operations (E5–E7).

use std::sync::Arc;

use esgm_core::{
    AddError, ComputeError, CreateError, EntityStructure, EntityTrajectoryStructure, Esgm,
    LookupError, QueryError, RegistrationError, Sample, SensorError, SubscribeOptions, Time,
    TrajectorySpec, esgm::LogLevel, millis,
};

use super::{WAIT, reading, register_reading, wait_stored, x_of};
use crate::Harness;

/// Unknown names get the seed's errors, with a suggestion when one is close.
pub fn unknown_names_get_the_seed_errors<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    e.create_primitive_entity_trajectory_structure("blobs", "Reading").unwrap();
    let err = e.get_entity_trajectory_structure("blobz").unwrap_err();
    assert_eq!(err.to_string(), "no entity trajectory structure `blobz`; did you mean `blobs`?");
    assert!(matches!(
        e.destroy_entity_trajectory_structure("nope"),
        Err(LookupError::NoSuchEntityStructure { .. })
    ));
    assert!(matches!(
        e.create_primitive_entity_trajectory_structure("x", "Readin"),
        Err(CreateError::NoSuchEntityStructureType { suggestion: Some(_), .. })
    ));
    assert!(matches!(
        e.create_entity_trajectory_structure("x", "camera", 0, 0, millis(10), 0, 0),
        Err(CreateError::NoSuchSensor { .. })
    ));
    assert!(matches!(
        e.create_primitive_entity_trajectory_structure("blobs", "Reading"),
        Err(CreateError::EntityStructureAlreadyExists { .. })
    ));
    assert!(matches!(
        e.remove_sensor_interface("cam"),
        Err(RegistrationError::NoSuchSensor { .. })
    ));
    assert!(matches!(e.remove_comp_unit("cu"), Err(RegistrationError::NoSuchCompUnit { .. })));
    let s = Arc::new(|q: Time| -> Result<EntityStructure, SensorError> { Ok(reading(q, 0.0)) });
    assert!(matches!(
        e.add_sensor_interface("cam", "Nope", s.clone()),
        Err(RegistrationError::NoSuchEntityStructureType { .. })
    ));
    e.add_sensor_interface("cam", "Reading", s.clone()).unwrap();
    assert!(matches!(
        e.add_sensor_interface("cam", "Reading", s),
        Err(RegistrationError::SensorAlreadyExists { .. })
    ));
}

/// E5: a destroyed name can be reused; old handles report the trajectory is gone.
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

/// E5: re-pointing a name keeps its subscribers (they see the new stream from then
/// on) and its handles; a computed trajectory reading the name follows it too.
pub fn re_pointing_keeps_subscribers_and_handles<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let copy = |i: &[Sample], _: Time| -> Result<EntityStructure, ComputeError> {
        Ok((*i[0].structure).clone())
    };
    e.add_comp_unit("copy", "Reading", vec!["Reading".into()], Arc::new(copy)).unwrap();
    let handle = e.create_primitive_entity_trajectory_structure("r", "Reading").unwrap();
    let downstream = e.create_computed_entity_trajectory_structure("d", "copy", &["r"]).unwrap();
    let sub = handle.subscribe(SubscribeOptions::default()).unwrap();
    let t0 = h.now();
    handle.add(reading(t0, 1.0)).unwrap();
    e.create_trajectory(TrajectorySpec::primitive("r", "Reading").replace()).unwrap();
    assert!(handle.get_latest().is_err(), "the handle now reaches the new, empty trajectory");
    handle.add(reading(t0 + 1, 2.0)).unwrap();
    let got: Vec<_> = (0..2).map(|_| sub.recv_timeout(WAIT).map(|s| x_of(&s))).collect();
    assert_eq!(got, vec![Ok(Some(1.0)), Ok(Some(2.0))]);
    wait_stored(&downstream, 2);
    // Re-pointing may not change the type (readers were checked against it) nor make
    // the name read itself.
    assert!(matches!(
        e.create_trajectory(TrajectorySpec::primitive("r", "Image").replace()),
        Err(CreateError::TypeChange { .. })
    ));
    let looped = e.create_trajectory(TrajectorySpec::computed("r", "copy", ["d"]).replace());
    assert!(matches!(looped, Err(CreateError::Cycle { .. })), "{looped:?}");
}

/// T4: only primitive trajectories take structures from outside.
pub fn external_adds_only_on_primitive<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let s = Arc::new(|q: Time| -> Result<EntityStructure, SensorError> { Ok(reading(q, 0.0)) });
    e.add_sensor_interface("cam", "Reading", s).unwrap();
    let t = e.create_entity_trajectory_structure("s", "cam", 0, 0, millis(100), 0, 0).unwrap();
    assert!(matches!(t.add(reading(h.now(), 1.0)), Err(AddError::OperationNotSupported { .. })));
}

/// E6: a sensor or unit in use cannot be removed; once its users are gone it can.
pub fn in_use_sensors_and_units_cannot_be_removed<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let s = Arc::new(|q: Time| -> Result<EntityStructure, SensorError> { Ok(reading(q, 0.0)) });
    e.add_sensor_interface("cam", "Reading", s).unwrap();
    e.create_entity_trajectory_structure("s", "cam", 0, 0, millis(100), 0, 0).unwrap();
    let err = e.remove_sensor_interface("cam").unwrap_err();
    assert_eq!(err.to_string(), "`cam` is used by s");
    e.destroy_entity_trajectory_structure("s").unwrap();
    e.remove_sensor_interface("cam").unwrap();
    assert!(e.sensors().is_empty());
}

/// E7: stats, memory stats, ping, reset, log level.
pub fn stats_memory_ping_reset_log_level<H: Harness>(h: &H) {
    register_reading(h);
    let e = h.esgm();
    let t = e.create_primitive_entity_trajectory_structure("r", "Reading").unwrap();
    let img = e.create_primitive_entity_trajectory_structure("img", "Image").unwrap();
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
    let stats = e.stats();
    let r = stats.trajectories.iter().find(|(i, _, _)| i.name == "r").unwrap();
    assert_eq!(r.1.added, 10);
    let m = e.memory_stats();
    assert_eq!((m.trajectories, m.stored_samples), (2, 12));
    assert!(m.approx_bytes >= 64 * 1024 && m.approx_bytes < 2 * 64 * 1024, "{}", m.approx_bytes);
    e.reset();
    assert_eq!(e.memory_stats().stored_samples, 0);
    e.set_log_level(LogLevel::Debug);
    assert_eq!(e.log_level(), LogLevel::Debug);
    assert_eq!(e.trajectories().len(), 2);
}
