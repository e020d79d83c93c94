//! `compare`: two recordings aligned by valid time, differences named by valid time,
//! attribute and both values.

// Test code: a failed unwrap is a failed test with a message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::Path;

#[path = "common/fixtures.rs"]
mod fixtures;
use fixtures::{primitive as info, robot};

fn image(i: i64) -> EntityStructure {
    fixtures::image(i, 4, 2)
}

use esgm_core::library::{Image, RobotState};
use esgm_core::{Attr, Entity, EntityStructure, ValueSort};
use esgm_recording::{
    Alignment, CompareError, CompareOptions, Presence, RecordOptions, Recording, RecordingWriter,
    TypeSchema, compare,
};

/// A recording of `robot_state` (robot types `schema`) and `images`, each structure
/// passed through `edit` first (return `None` to leave it out).
struct Recipe<'a> {
    n: i64,
    robot_schema: TypeSchema,
    edit_robot: &'a dyn Fn(i64, EntityStructure) -> Option<EntityStructure>,
    edit_image: &'a dyn Fn(i64, EntityStructure) -> Option<EntityStructure>,
    extra: bool,
}

impl Default for Recipe<'_> {
    fn default() -> Self {
        Self {
            n: 20,
            robot_schema: TypeSchema::collect(RobotState::entity_structure_type(), &|_| None),
            edit_robot: &|_, e| Some(e),
            edit_image: &|_, e| Some(e),
            extra: false,
        }
    }
}

fn write(path: &Path, r: &Recipe) {
    let mut w = RecordingWriter::create(path, RecordOptions::default()).expect("create");
    let rt =
        w.add_trajectory(info("robot_state", "RobotState"), r.robot_schema.clone()).expect("add");
    let it = w
        .add_trajectory(
            info("images", "Image"),
            TypeSchema::collect(Image::entity_structure_type(), &|_| None),
        )
        .expect("add");
    let xt = r.extra.then(|| {
        w.add_trajectory(
            info("extra", "RobotState"),
            TypeSchema::collect(RobotState::entity_structure_type(), &|_| None),
        )
        .expect("add")
    });
    for i in 0..r.n {
        if let Some(e) = (r.edit_robot)(i, robot(i)) {
            w.write(rt, &e, 5_000 + i, 6_000 + i).expect("write");
        }
        if let Some(e) = (r.edit_image)(i, image(i)) {
            w.write(it, &e, 7_000 + i, 8_000 + i).expect("write");
        }
        if let Some(x) = xt {
            w.write(x, &robot(i), 5_000 + i, 6_000 + i).expect("write");
        }
    }
    w.finish().expect("finish");
}

fn pair(a: &Recipe, b: &Recipe) -> (tempfile::TempDir, Recording, Recording) {
    let dir = tempfile::tempdir().expect("tempdir");
    write(&dir.path().join("a.mcap"), a);
    write(&dir.path().join("b.mcap"), b);
    let ra = Recording::open(dir.path().join("a.mcap")).expect("open a");
    let rb = Recording::open(dir.path().join("b.mcap")).expect("open b");
    (dir, ra, rb)
}

#[test]
fn identical_recordings_match() {
    let (_dir, a, b) = pair(&Recipe::default(), &Recipe::default());
    let report = compare(&a, &b, &CompareOptions::default()).expect("compare");
    assert!(!report.differs(), "{report:#?}");
    assert_eq!(report.trajectories.len(), 2);
    for t in &report.trajectories {
        assert_eq!((t.count_a, t.count_b, t.matched, t.differing), (20, 20, 20, 0), "{t:?}");
        assert_eq!(t.largest_deviation, None);
    }
}

#[test]
fn one_changed_attribute_is_found_with_its_valid_time_and_both_values() {
    let changed = Recipe {
        edit_robot: &|i, e| Some(if i == 7 { e.with("y", 42.0) } else { e }),
        ..Default::default()
    };
    let (_dir, a, b) = pair(&Recipe::default(), &changed);
    let report = compare(&a, &b, &CompareOptions::default()).expect("compare");
    assert!(report.differs());
    let t = report.trajectories.iter().find(|t| t.name == "robot_state").expect("compared");
    assert_eq!((t.matched, t.differing), (20, 1));
    let d = t.first_difference.clone().expect("a difference");
    assert_eq!(
        (d.valid_time, d.attribute.as_str(), d.a.as_str(), d.b.as_str()),
        (1_700, "y", "-7", "42")
    );
    let dev = t.largest_deviation.clone().expect("a deviation");
    assert_eq!(
        (dev.leaf.attribute.as_str(), dev.leaf.deviation, dev.valid_time),
        ("y", 49.0, 1_700)
    );
    let images = report.trajectories.iter().find(|t| t.name == "images").expect("compared");
    assert!(!images.differs(), "{images:?}");
}

#[test]
fn a_numeric_tolerance_accepts_small_deviations_and_reports_the_largest() {
    let nudged = Recipe {
        edit_robot: &|i, e| {
            let x = e.get("x").and_then(|v| v.as_double()).unwrap_or_default();
            Some(e.with("x", x + i as f64 * 1e-7))
        },
        ..Default::default()
    };
    let (_dir, a, b) = pair(&Recipe::default(), &nudged);
    let exact = compare(&a, &b, &CompareOptions::default()).expect("compare");
    assert!(exact.differs(), "bitwise by default");
    let tolerant =
        compare(&a, &b, &CompareOptions::new().value_tolerance(Some(1e-3))).expect("compare");
    assert!(!tolerant.differs(), "{tolerant:#?}");
    let t = &tolerant.trajectories[0];
    let dev = t.largest_deviation.clone().expect("deviation reported even within tolerance");
    assert_eq!((dev.leaf.attribute.as_str(), dev.valid_time), ("x", 1_000 + 19 * 100));
    assert!((dev.leaf.deviation - 19e-7).abs() < 1e-9, "{dev:?}");
}

#[test]
fn structures_and_trajectories_only_in_one_file_are_reported() {
    let more = Recipe { extra: true, ..Default::default() };
    let fewer = Recipe { edit_robot: &|i, e| (i != 3).then_some(e), ..Default::default() };
    let (_dir, a, b) = pair(&more, &fewer);
    let report = compare(&a, &b, &CompareOptions::default()).expect("compare");
    assert!(report.differs());
    let robot = report.trajectories.iter().find(|t| t.name == "robot_state").expect("compared");
    assert_eq!(
        (robot.count_a, robot.count_b, robot.matched, robot.only_in_a, robot.only_in_b),
        (20, 19, 19, 1, 0)
    );
    assert_eq!(robot.first_only_in_a, Some(1_300));
    let extra = report.trajectories.iter().find(|t| t.name == "extra").expect("reported");
    assert_eq!((extra.presence, extra.count_a, extra.count_b), (Presence::OnlyInA, 20, 0));
    let reverse = compare(&b, &a, &CompareOptions::default()).expect("compare");
    let extra = reverse.trajectories.iter().find(|t| t.name == "extra").expect("reported");
    assert_eq!(extra.presence, Presence::OnlyInB);
    // --only narrows, and an unknown name is refused by name.
    let only = compare(&a, &b, &CompareOptions::new().only(["images"])).expect("compare");
    assert!(!only.differs(), "{only:#?}");
    let e = compare(&a, &b, &CompareOptions::new().only(["nope"])).expect_err("unknown");
    assert!(
        matches!(e, CompareError::NoSuchTrajectory { .. }) && e.to_string().contains("nope"),
        "{e}"
    );
}

#[test]
fn a_type_difference_names_the_attribute() {
    let mut t = RobotState::entity_structure_type();
    t.attributes.push(Attr::new("speed", ValueSort::Double));
    let other = Recipe {
        robot_schema: TypeSchema::collect(t, &|_| None),
        edit_robot: &|_, e| Some(e.with("speed", 1.0)),
        ..Default::default()
    };
    let (_dir, a, b) = pair(&Recipe::default(), &other);
    let report = compare(&a, &b, &CompareOptions::default()).expect("compare");
    let robot = report.trajectories.iter().find(|t| t.name == "robot_state").expect("compared");
    let d = robot.type_difference.clone().expect("types differ");
    assert_eq!((d.type_name.as_str(), d.attribute.as_deref()), ("RobotState", Some("speed")));
    assert_eq!(robot.first_difference.clone().expect("values differ").attribute, "speed");
}

#[test]
fn images_are_compared_byte_for_byte() {
    let flipped = Recipe {
        edit_image: &|i, mut e| {
            if i == 4 {
                let mut px = e
                    .get("image_data")
                    .and_then(|v| v.as_octets())
                    .map(|o| o.to_vec())
                    .unwrap_or_default();
                px[5] ^= 0xFF;
                e.set("image_data", esgm_core::Octets::new(px));
            }
            Some(e)
        },
        ..Default::default()
    };
    let (_dir, a, b) = pair(&Recipe::default(), &flipped);
    let report =
        compare(&a, &b, &CompareOptions::new().value_tolerance(Some(1000.0))).expect("compare");
    let images = report.trajectories.iter().find(|t| t.name == "images").expect("compared");
    assert_eq!(images.differing, 1, "bytes are exact whatever the numeric tolerance");
    let d = images.first_difference.clone().expect("differs");
    assert_eq!((d.valid_time, d.attribute.as_str()), (1_000 + 4 * 250, "image_data[5]"));
}

#[test]
fn nearest_alignment_pairs_within_the_tolerance() {
    let shifted = Recipe {
        edit_robot: &|_, mut e| {
            e.valid_time += 3;
            Some(e)
        },
        ..Default::default()
    };
    let (_dir, a, b) = pair(&Recipe::default(), &shifted);
    let exact = compare(&a, &b, &CompareOptions::new().only(["robot_state"])).expect("compare");
    let t = &exact.trajectories[0];
    assert_eq!((t.matched, t.only_in_a, t.only_in_b), (0, 20, 20));
    let near =
        compare(&a, &b, &CompareOptions::new().only(["robot_state"]).nearest(5)).expect("compare");
    let t = &near.trajectories[0];
    assert_eq!(near.alignment, Alignment::Nearest { within: 5 });
    assert_eq!((t.matched, t.only_in_a, t.only_in_b, t.differing), (20, 0, 0, 0), "{t:?}");
    let d =
        compare(&a, &b, &CompareOptions::new().only(["robot_state"]).nearest(2)).expect("compare");
    assert_eq!(d.trajectories[0].matched, 0, "3 ns apart is not within 2 ns");
}
