//! Stream operators (G2–G4): pure algorithms that turn input streams into new streams.
//!
//! Each operator here is a plain state machine: the caller feeds it items and gets back
//! whatever output became decidable. Nothing in this module starts a thread or reads a
//! clock, so the runtimes (in-process and shared memory) drive the very same code, and
//! every rule can be tested by feeding hand-made stamps.

pub mod sync;
