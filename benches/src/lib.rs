//! # esgm-benches
//!
//! The `esgm-bench` scenario runner (`src/bin/esgm-bench.rs`) and the criterion
//! micro-benchmarks of the core (`benches/`).
//!
//! ## How `esgm-bench` is built
//! - A [`Scenario`] measures one thing on one runtime or peer and returns one
//!   [`Measurement`] per wait strategy (busy-spinning or blocking receiver). Each
//!   scenario lives in its own file under [`scenarios`]; adding one means one file and
//!   one line in [`scenarios::all`].
//! - Every figure is compared with a baseline measured **in the same run** (a
//!   measurement names its baseline scenario; the row with that name and the same wait
//!   is the reference), because absolute numbers on a shared, noisy machine mean little
//!   while ratios hold. Goals an issue sets for such ratios are [`Target`]s: printed
//!   under the table with the ratio measured, never asserted.
//! - Percentiles come from `hdrhistogram` ([`Latency`]), at three significant digits.
//! - A [`Report`] is what `--json` writes (`{"scenarios":[{"name","payload_bytes","wait",
//!   "n","p50_ns","p99_ns","p999_ns","max_ns", …}]}`, extra fields only added, never
//!   renamed) and what [`table::render`] prints, with the ratios.
//! - Latency between two threads or processes is measured as a round trip halved, on
//!   one thread's monotonic clock, so no two clocks are compared; where one thread both
//!   sends and receives, the one-way time is measured directly. Each row says which
//!   ([`Method`]).
//!
//! ## Across processes
//! The shared-memory scenarios (`floor-iceoryx2`, `uds-small`, `esgm-small`,
//! `esgm-image`, `uds-image`) measure against a **peer process**: `esgm-bench` starts
//! itself again with hidden `--peer …` options ([`peer_role`]), one peer per
//! measurement, pinned to the peer core under `--pin`. Both meet in a domain (iceoryx2
//! service namespace, socket name) unique to the measurement, holding the measuring
//! process's id. Nothing waits forever: every wait goes through [`patience::Patience`],
//! which notices a peer that exited (within 20 ms) or hangs (10 s), and a peer that is
//! not reaped normally is killed and its shared memory cleaned up
//! ([`peer_process::PeerProcess`]). A peer whose measuring process vanished gives up on
//! its own after 10 s.
//!
//! Scenarios with several peers (a coordinator, a camera, unit workers, four
//! subscribers) tell each which it is with a hidden `--peer-arg`. Besides the latency
//! rows, a run collects memory figures (the JSON's `memory` array) and rows that could
//! not run here (`skipped`, e.g. Zenoh without the `zenoh` feature), and `--plots DIR`
//! draws PNG charts ([`plots`]).
//!
//! Rows keep the two waits of the JSON contract (`spin`, `event`); esgm's default
//! spin-then-block strategy, an `event` row too, is told apart by a `-default` name
//! suffix and the `wait_strategy` field ([`wait_mode`]).
//!
//! This library only structures the benchmark binaries, so it follows the conventions
//! of binaries: errors are `anyhow` with context, and a failed scenario stops the run
//! with a message naming it.
#![deny(missing_docs)]

pub mod args;
pub mod config;
pub mod cpu;
pub mod domain_end;
pub mod hop_steps;
pub mod inbox;
pub mod json;
pub mod latency;
pub mod patience;
pub mod peer_process;
pub mod peer_role;
pub mod pin;
pub mod plots;
pub mod python_env;
pub mod refsys;
pub mod report;
pub mod runner;
pub mod scenario;
pub mod scenarios;
pub mod table;
pub mod target;
pub mod wait_mode;

pub use config::RunConfig;
pub use latency::Latency;
pub use report::{Measurement, Method, Report, Wait};
pub use scenario::{Context, Scenario};
pub use target::Target;
pub use wait_mode::WaitMode;
