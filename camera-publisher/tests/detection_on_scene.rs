//! The tutorial's pipeline on rendered scenes: the camera's frames through the blob
//! detector, selection and driving direction, checked against the scene's ground truth
//! and against a golden file.

// Helpers outside `#[test]` functions: a failed unwrap there is a failed test too.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::fmt::Write as _;
use std::path::PathBuf;

use camera_publisher::{FrameSource, SyntheticScene};
use cu_workers::{
    BlobDetectionConfig, BlobDetector, ComputeDirection, Connectivity, DrivingDirectionConfig,
    select_blob,
};
use esgm_core::library::{Blob, RobotState};
use esgm_core::time::{Time, millis, secs};

const TIMES: [Time; 5] = [0, 370_000_000, 1_900_000_000, 7_300_000_000, 1_700_000_000_000_000_000];

/// The detected blob nearest to `truth`.
fn nearest(found: &[Blob], truth: &Blob) -> Blob {
    *found
        .iter()
        .min_by_key(|b| (b.x - truth.x).pow(2) + (b.y - truth.y).pow(2))
        .expect("some blob was detected")
}

#[test]
fn detection_recovers_the_ground_truth() {
    let scenes = [(0, 3), (1, 1), (2, 4), (3, 6), (4, 9)];
    for (i, (seed, blobs)) in scenes.into_iter().enumerate() {
        // Discs are convex, so either connectivity must find the same blobs.
        let connectivity = if i % 2 == 0 { Connectivity::Eight } else { Connectivity::Four };
        let mut detector =
            BlobDetector::new(BlobDetectionConfig { connectivity, ..Default::default() });
        let scene = SyntheticScene::builder().blobs(blobs).seed(seed).create().unwrap();
        let mut pixels = vec![0u8; scene.frame_len()];
        for t in TIMES {
            // Straight into a reused buffer, as a shared-memory camera would.
            scene.render_into(t, &mut pixels).unwrap();
            let found = detector.detect_pixels(640, 480, 0, &pixels).unwrap().items;
            let truth = scene.truth(t);
            let context = format!("seed {seed}, t {t}, {connectivity:?}");
            assert_eq!(found.len(), truth.len(), "{context}: {found:?} vs {truth:?}");
            assert!(found.windows(2).all(|w| w[0].size >= w[1].size), "{context}: unsorted");
            for want in &truth {
                let got = nearest(&found, want);
                assert!(
                    (got.x - want.x).abs() <= 1 && (got.y - want.y).abs() <= 1,
                    "{context}: centre {got:?} vs truth {want:?}"
                );
                let error = (got.size - want.size).abs() as f64 / want.size as f64;
                assert!(error <= 0.10, "{context}: size {got:?} vs truth {want:?}");
            }
        }
    }
}

#[test]
fn selection_follows_the_largest_disc() {
    let scene = SyntheticScene::builder().blobs(4).seed(11).create().unwrap();
    let mut detector = BlobDetector::default();
    for t in TIMES {
        let blobs = detector.detect(&scene.frame(t)).unwrap();
        let largest = scene.truth(t).into_iter().max_by_key(|b| b.size).unwrap();
        let chosen = select_blob(&blobs).unwrap();
        assert!((chosen.x - largest.x).abs() <= 1 && (chosen.y - largest.y).abs() <= 1);
    }
    let empty = SyntheticScene::builder().blobs(0).create().unwrap();
    assert_eq!(select_blob(&detector.detect(&empty.frame(0)).unwrap()), None);
}

/// One line per frame: time, the detected blobs, the selected one, and the driving
/// direction for a robot at the origin facing +y.
fn pipeline_report() -> String {
    let scene = SyntheticScene::builder().blobs(4).seed(42).create().unwrap();
    let mut detector = BlobDetector::default();
    let unit = ComputeDirection::new(DrivingDirectionConfig::default()).unwrap();
    let robot = RobotState { x: 0.0, y: 0.0, dir: 90.0 };
    let mut out = String::from("# t_ns | blobs x,y,size largest first | selected | dir speed\n");
    for t in [0, millis(250), secs(1), secs(5), secs(13)] {
        let blobs = detector.detect(&scene.frame(t)).unwrap();
        let list: Vec<String> =
            blobs.items.iter().map(|b| format!("{},{},{}", b.x, b.y, b.size)).collect();
        let selected = select_blob(&blobs).unwrap();
        let drive = unit.compute(&robot, &selected);
        writeln!(
            out,
            "{t} | {} | {},{},{} | {:.6} {:.6}",
            list.join(" "),
            selected.x,
            selected.y,
            selected.size,
            drive.dir,
            drive.speed
        )
        .unwrap();
    }
    out
}

/// Compares with `tests/golden/pipeline_seed42.txt`; `UPDATE_GOLDEN=1` rewrites it.
#[test]
fn pipeline_matches_golden_file() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden/pipeline_seed42.txt");
    let actual = pipeline_report();
    if std::env::var_os("UPDATE_GOLDEN").is_some() {
        std::fs::write(&path, &actual).unwrap();
    }
    let expected = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!("{}: {e}; run with UPDATE_GOLDEN=1 to create it", path.display())
    });
    assert_eq!(actual, expected, "pipeline output changed; if intended, run with UPDATE_GOLDEN=1");
}
