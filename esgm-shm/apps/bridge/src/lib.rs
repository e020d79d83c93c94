//! # esgm-bridge
//!
//! esgm beyond one machine (SPEC P5): a process per host, `esgm-bridge` (run as
//! `esgm bridge`), that joins a Zenoh session and carries chosen trajectories of its
//! domain to the domains of other hosts, keeping what a plain Zenoh bridge does not:
//! valid time, type checking, policies and accounted losses.
//!
//! ```text
//! host A, domain `a`                                  host B, domain `b`
//! writer ──iceoryx2──▶ esgm-bridge ══ Zenoh ══▶ esgm-bridge ──▶ primitive trajectory
//!                      (export)   esgm/a/<name>   (import)        written by the bridge
//! ```
//!
//! ## Design decisions
//! - **Its own binary.** Zenoh takes minutes to build on two cores; keeping it out of
//!   `esgm-cli` keeps the demo's and the CLI's build as they were. `esgm bridge …`
//!   runs this binary as git and cargo run their external subcommands.
//! - **Zenoh is a feature** (`zenoh`, on by default; the binary needs it). Off, the
//!   library is [`wire`] and the small helpers that need no session, so esgm-fuzz
//!   fuzzes the wire decoder without a Zenoh build.
//! - **Keys.** `esgm/<domain>/<trajectory>` ([`key`]): the data, and the exporter's
//!   queryable for type, history and remote queries ([`serve`]).
//! - **The payload is the shared-memory archive.** The exporter reads the trajectory's
//!   iceoryx2 service itself and sends the writer's codec bytes unchanged behind a
//!   small header with the writer's sequence number, add time and type ([`wire`],
//!   [`export`]). The importer validates them like any bytes from another process;
//!   malformed messages are counted and dropped.
//! - **The type travels.** The importer registers the exporter's type, or refuses the
//!   trajectory naming the attribute that differs ([`types`]).
//! - **An imported trajectory is an ordinary one**: a primitive of the local domain
//!   with the exporter's cache, written by the bridge ([`import`]). Valid and create
//!   times are kept, the add time is the importer's, so its add delay is the
//!   cross-host delay.
//! - **Losses are counted, with their cause** ([`stats`]): gaps in the writer's
//!   sequence numbers, within one run of the exporter or across its restart, minus
//!   what the exporter skipped on purpose (`--latest-only`, `--max-rate`).
//! - **Late joiners** get the exporter's last messages up to the trajectory's cache
//!   bound from its queryable (`?esgm=history`).
#![deny(missing_docs)]

#[cfg(feature = "zenoh")]
pub mod ask;
#[cfg(feature = "zenoh")]
pub mod export;
#[cfg(feature = "zenoh")]
pub mod import;
pub mod key;
#[cfg(feature = "zenoh")]
pub mod remote;
#[cfg(feature = "zenoh")]
pub mod serve;
#[cfg(feature = "zenoh")]
pub mod session;
pub mod stats;
pub mod times;
pub mod types;
pub mod wire;
