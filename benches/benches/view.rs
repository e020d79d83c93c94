//! Criterion micro-benchmarks of the typed view (M5) against decoding, both from the
//! same archive in the same run.
//!
//! Run: `cargo bench -p esgm-benches --bench view` (1 s warm-up, 2 s measurement per
//! benchmark). `-- --test` runs each one once.
//!
//! What is measured, per structure:
//! - `robot_state/view`: `RobotState::view(archived)` and reading its three fields;
//!   `robot_state/decode`: `codec::decode` into an owned structure and
//!   `RobotState::from_structure`, what a reader without the view does.
//! - `image/view`: `Image::view(archived)` of a 640×480 RGB frame and summing 64
//!   bytes of its pixels, read in place; `image/decode`: the same after decoding,
//!   which copies the 921,600 bytes.
// A benchmark that cannot set itself up should stop at once and say why.
#![allow(clippy::expect_used)]

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use esgm_core::Entity;
use esgm_core::codec;
use esgm_core::library::{Image, RobotState};

fn sum(bytes: &[u8]) -> u64 {
    bytes.iter().take(64).map(|b| u64::from(*b)).sum()
}

fn robot_state(c: &mut Criterion) {
    let es = RobotState { x: 1.5, y: -2.0, dir: 90.0 }.to_structure("robot1", 10, 11);
    let bytes = codec::encode(&es).expect("encode");
    let archived = codec::access(&bytes).expect("access");
    let mut g = c.benchmark_group("robot_state");
    g.bench_function("view", |b| {
        b.iter(|| {
            let v = RobotState::view(black_box(archived)).expect("view");
            v.x() + v.y() + v.dir()
        })
    });
    g.bench_function("decode", |b| {
        b.iter(|| {
            let owned = codec::decode(black_box(archived)).expect("decode");
            let r = RobotState::from_structure(&owned).expect("typed");
            r.x + r.y + r.dir
        })
    });
    g.finish();
}

fn image(c: &mut Criterion) {
    let img = Image { width: 640, height: 480, format: 1, image_data: vec![3u8; 921_600].into() };
    let bytes = codec::encode(&img.to_structure("cam", 1, 1)).expect("encode");
    let archived = codec::access(&bytes).expect("access");
    let mut g = c.benchmark_group("image");
    g.bench_function("view", |b| {
        b.iter(|| sum(Image::view(black_box(archived)).expect("view").image_data()))
    });
    g.bench_function("decode", |b| {
        b.iter(|| {
            let owned = codec::decode(black_box(archived)).expect("decode");
            sum(&Image::from_structure(&owned).expect("typed").image_data)
        })
    });
    g.finish();
}

fn settings() -> Criterion {
    Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2))
}

criterion_group! { name = benches; config = settings(); targets = robot_state, image }
criterion_main!(benches);
