//! The API's conveniences over the IDL names, on both sides: the most current value
//! (`get_latest_vtime`), types registered under their own name, structures given
//! their times by name, statistics by trajectory name, and one `prelude` import.

use esgm_core::prelude::*;
use esgm_core::{QueryError, library::RobotState};

use super::{read, reading, register_reading, wait_visible, x_of};
use crate::Harness;

/// T1: `get_latest_vtime` is the sample with the latest valid time, which is not the
/// last added when structures arrive out of order; `get_latest` stays the last added.
/// Both sides answer alike; an empty trajectory has no value.
pub fn get_latest_vtime_is_the_most_current<H: Harness>(h: &H) {
    register_reading(h);
    let w = h.esgm().create_primitive_entity_trajectory_structure("r", "Reading").unwrap();
    let r = read(h, "r");
    for side in [&w, &r] {
        assert!(matches!(side.get_latest_vtime(), Err(QueryError::ValueNotAvailable { .. })));
    }
    let t0 = h.now();
    for (k, dt) in [(1.0, 10), (3.0, 30), (2.0, 20)] {
        w.add(reading(t0 + dt, k)).unwrap();
    }
    wait_visible(&w, &r);
    for side in [&w, &r] {
        assert_eq!(x_of(&side.get_latest().unwrap()), Some(2.0), "the last added");
        let current = side.get_latest_vtime().unwrap();
        assert_eq!((current.valid_time(), x_of(&current)), (t0 + 30, Some(3.0)));
    }
    // Of two samples valid at the same latest time, the one added last.
    w.add(reading(t0 + 30, 4.0)).unwrap();
    wait_visible(&w, &r);
    for side in [&w, &r] {
        assert_eq!(x_of(&side.get_latest_vtime().unwrap()), Some(4.0));
    }
}

/// E1 and M3 without repeated names or unlabelled times: `create_type` registers a
/// type under its own name (seen by the other side), `create_type_of` a derived
/// struct's; `EntityStructure::named(..).valid_at(..).created_at(..)` keeps both times
/// apart; `stats().trajectories` is a map by name on both sides.
pub fn types_structures_and_stats_by_name<H: Harness>(h: &H) {
    let e = h.esgm();
    e.create_type(EntityStructureType::new("Pair").attr("a", ValueSort::Long)).unwrap();
    assert!(e.create_type(EntityStructureType::new("Pair")).is_err(), "registered once");
    for side in [e, h.reader()] {
        let t = side.get_entity_structure_type("Pair").unwrap();
        assert_eq!(t.attributes.len(), 1);
    }
    // A derived struct's type under its own name (the library has RobotState: taken).
    assert!(e.create_type_of::<RobotState>().is_err());
    let w = e.create_primitive_entity_trajectory_structure("p", "Pair").unwrap();
    let r = read(h, "p");
    let t0 = h.now();
    let es = EntityStructure::named("p").valid_at(t0 - 5).created_at(t0).with("a", 7i64);
    assert_eq!((es.valid_time, es.create_time), (t0 - 5, t0));
    assert_eq!(es, EntityStructure::new("p", t0 - 5, t0).with("a", 7i64), "as `new`");
    w.add(es).unwrap();
    w.add(EntityStructure::named("p").at(t0).with("a", 8i64)).unwrap();
    wait_visible(&w, &r);
    let first = r.get_nth_latest(1).unwrap();
    assert_eq!((first.valid_time(), first.create_time()), (t0 - 5, t0));
    let stats = e.stats().unwrap();
    assert_eq!(stats.trajectories["p"].stats.added, 2);
    assert_eq!(stats.get("p").map(|p| p.info.type_name.as_str()), Some("Pair"));
    assert!(stats.get("nope").is_none());
    assert!(
        crate::wait_for(super::WAIT, || h
            .reader()
            .stats()
            .unwrap()
            .get("p")
            .is_some_and(|p| p.stats.added == 2)),
        "the reader's stats by name: {:?}",
        h.reader().stats().unwrap().get("p")
    );
}
