//! # esgm-benches
//!
//! The `esgm-bench` scenario runner (`src/bin/esgm-bench.rs`) and the criterion
//! micro-benchmarks of the core (`benches/`).
//!
//! ## How `esgm-bench` is built
//! - A [`Scenario`] measures one thing on one runtime or peer and returns one
//!   [`Measurement`] per wait strategy (busy-spinning or blocking receiver). Each
//!   scenario lives in its own file under [`scenarios`]; adding one (the shared-memory
//!   `floor-iceoryx2`, `esgm-small`, `esgm-image`, `uds-small`, `uds-image`) means one
//!   file and one line in [`scenarios::all`].
//! - Every figure is compared with a baseline measured **in the same run** (a
//!   measurement names its baseline scenario; the row with that name and the same wait
//!   is the reference), because absolute numbers on a shared, noisy machine mean little
//!   while ratios hold.
//! - Percentiles come from `hdrhistogram` ([`Latency`]), at three significant digits.
//! - A [`Report`] is what `--json` writes (`{"scenarios":[{"name","payload_bytes","wait",
//!   "n","p50_ns","p99_ns","p999_ns","max_ns", …}]}`, extra fields only added, never
//!   renamed) and what [`table::render`] prints, with the ratios.
//! - Latency between two threads is measured as a round trip halved, on one thread's
//!   monotonic clock, so no two clocks are compared; where one thread both sends and
//!   receives, the one-way time is measured directly. Each row says which ([`Method`]).
//!
//! This library only structures the benchmark binaries, so it follows the conventions
//! of binaries: errors are `anyhow` with context, and a failed scenario stops the run
//! with a message naming it.
#![deny(missing_docs)]

pub mod args;
pub mod config;
pub mod inbox;
pub mod json;
pub mod latency;
pub mod pin;
pub mod report;
pub mod runner;
pub mod scenario;
pub mod scenarios;
pub mod table;

pub use config::RunConfig;
pub use latency::Latency;
pub use report::{Measurement, Method, Report, Wait};
pub use scenario::{Context, Scenario};
