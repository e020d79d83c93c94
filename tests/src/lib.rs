//! Test support for esgm: the runtime-generic conformance suite, and harnesses.
//!
//! Every semantic rule of the ESGM interface is written once, in [`conformance`], as a
//! function generic over a [`Harness`]; [`conformance_tests!`] turns the whole suite
//! into `#[test]`s for one runtime. The in-process runtime runs it in
//! `tests/in_process.rs`; the shared-memory runtime runs the same functions in
//! `tests/shm.rs`.
//!
//! A [`Harness`] has a writing side and a reading side: tests create and add through
//! [`Harness::esgm`] and query, subscribe and read statistics through
//! [`Harness::reader`]. On shared memory these are two connections — two locations, as
//! two processes of a robot — so each semantic is checked across the process
//! boundary, not only against the writing process's local store.
#![deny(missing_docs)]
// This crate is test code: a failed unwrap or a panic is a failed test with its message.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

pub mod conformance;
mod harness;

pub use harness::{Harness, InProcessHarness, ShmHarness, wait_for};
