//! esgm-fuzz: a fuzzer for everything esgm decodes from another process, host or file —
//! the codec's validation and access, a sample's header and payload as a reader checks
//! them, the control protocol's requests and answers, the admin channel's questions and
//! answers, blocking adds (the writer's request, the replica's answer), the bridge's
//! wire messages, recordings (MCAP files, damaged or crafted) and the configuration
//! parser. Run it as `esgm-fuzz --seconds N`.
//!
//! # Build it with overflow checks
//! `cargo build --profile fuzz -p esgm-fuzz` (then `target/fuzz/esgm-fuzz`): the
//! workspace's `fuzz` profile is `release` with `overflow-checks = true`, so arithmetic
//! on outside numbers that a release build would silently wrap panics and is a
//! finding. A debug build (the tests') checks overflow too, only slower.
//!
//! # Design
//! - **The code under test is the code that runs.** Each target calls the function a
//!   reader, the coordinator, a client or `esgm apply` calls
//!   ([`esgm_core::codec::access`], [`esgm_shm::check_sample`],
//!   [`esgm_shm::control::decode`] and the coordinator's
//!   [`esgm_shm::control::Registry`], [`esgm_shm::unstable::AdminReader`],
//!   [`esgm_shm::unstable::serve_blocking_add`] and
//!   [`esgm_shm::unstable::read_blocking_add_answer`], [`esgm_bridge::wire::decode`],
//!   [`esgm_recording::Recording`], [`esgm_cli::config::parse`]), never a copy. Where
//!   that code was private it is public and `#[doc(hidden)]` for this crate alone.
//! - **Inputs** start from valid ones (encodings of the library's types, a compound of
//!   every value sort, nesting up to the bound; a sample per structure and a reset;
//!   requests of every kind and the registry's answers; the tutorial and a file with
//!   every declaration) and are mutated ([`mutate`], [`text`], [`json`]): bit flips, byte sets,
//!   truncation, extension, splicing, 4- and 8-byte length and offset fields set to
//!   boundary values, deep nesting, long strings. Some are generated (random
//!   structures, nesting past the bound) or random bytes. A hand-written SplitMix64
//!   ([`rng`]) keeps a case repeatable from its seed and index alone.
//! - **A finding** is a panic, a hang (one case over `--hang-ms`), an abort (the
//!   process died: stack overflow, failed allocation) or a broken promise
//!   ([`target::Broken`]: an accepted archive must decode, a valid encoding must be
//!   accepted, an answer must be readable). A decoder's typed error is not one.
//! - **Isolation.** A stack overflow or an abort cannot be caught inside a process, so
//!   each target runs in a child process ([`runner`]); the parent ([`supervise`])
//!   finds the case that killed a child, saves it and goes on after it.
//! - No coverage feedback: cargo-fuzz and libFuzzer need a nightly toolchain. The
//!   mutations aim at the formats' fields instead.

#![deny(missing_docs)]

pub mod buffer;
pub mod event;
pub mod json;
pub mod mutate;
pub mod report;
pub mod rng;
pub mod runner;
pub mod structures;
pub mod supervise;
pub mod target;
pub mod targets;
pub mod text;
