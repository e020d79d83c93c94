//! # esgm from C and C++
//!
//! (The modules mirror the header, one concept each; C and C++ programs use
//! `esgm.h`, not this crate's Rust items.)
//!
//! The C ABI of esgm: every operation of the seed's `esgm.idl` and
//! `entity_trajectory_structure.idl` (SPEC L3), over the same Rust API a program uses
//! (`esgm_shm::prelude`), on both runtimes. Its one header, `include/esgm.h`, is
//! generated from this crate by cbindgen (`tests/header.rs` fails when the committed
//! header differs; `ESGM_BLESS=1 cargo test -p esgm-c --test header` rewrites it). The
//! C++17 wrapper, `esgm-shm/cpp/include/esgm/esgm.hpp`, carries the conveniences.
//!
//! ## Design decisions
//! - **Handles, not pointers.** Every object a C program holds is a 64-bit handle into
//!   one table ([`handles`]): an index, a generation and the object's kind. A freed
//!   handle, a handle of another kind, a handle made up or copied from garbage is
//!   refused with `ESGM_INVALID_HANDLE` and a message naming what it is, never
//!   dereferenced, so a C bug is an error code, not memory corruption. The typed
//!   structs (`esgm_trajectory_t`, `esgm_sample_t`, …) give the compiler the kinds too.
//! - **A status from every function.** Values are named after the IDL's exceptions
//!   (`ESGM_NO_SUCH_ENTITY_STRUCTURE`, `ESGM_POLICY_VIOLATION`, …); the message of the
//!   last failed call on a thread, with the name that was wrong, is
//!   `esgm_last_error_message()` ([`status`]). A Rust panic is caught at the boundary
//!   and returned as `ESGM_INTERNAL`; it never unwinds into C.
//! - **Zero copy both ways.** A producer writes pixels into a loan of the trajectory's
//!   shared memory ([`image`]); a reader gets `const uint8_t*` into the writer's chunk,
//!   valid while it holds the sample's handle, whatever the writer does ([`sample`]).
//! - **Inputs are checked before use.** Null pointers, strings that are not UTF-8,
//!   indexes out of range and unknown enum values are refused with a message: enums
//!   cross as integers and are checked here, since a C compiler lets any value through.
//! - **Callbacks run on esgm's threads.** Units and sensors are C function pointers with
//!   a user pointer ([`units`], [`sensors`]); `esgm_free` waits for calls under way and
//!   calls none after it returns, then releases every user pointer it was given.
#![deny(missing_docs)]
// Every `extern "C"` function checks its pointers itself (null, alignment of what it
// writes is the caller's) and documents what it needs: clippy's lint asks for `unsafe
// fn`, which would move that burden to every C caller without adding a check.
#![allow(clippy::not_unsafe_ptr_arg_deref)]

pub mod add;
pub mod connect;
pub mod handles;
pub mod image;
pub mod query;
pub mod sample;
pub mod sensors;
pub mod spec;
pub mod status;
pub mod strings;
pub mod structure;
pub mod subscription;
pub mod trajectory;
pub mod types;
pub mod units;
pub mod values;
