//! # esgm-view
//!
//! A live [Foxglove](https://foxglove.dev) WebSocket server for an esgm domain, built
//! on the official `foxglove` SDK; run as `esgm view` (or `esgm-view`).
//!
//! ## Design decisions
//! - **Its own binary.** The SDK brings tokio and tungstenite; keeping it out of
//!   `esgm-cli` keeps the CLI's and the demo's build as they were. `esgm view …` runs
//!   this binary as git and cargo run their external subcommands.
//! - **Every trajectory is a channel** (topic `/<trajectory>`), created and closed as
//!   trajectories come and go in the domain ([`server`] polls the listing).
//! - **One encoder.** Images are `foxglove.RawImage` in protobuf and every other type is
//!   JSON with a JSON Schema, encoded by esgm-recording's [`esgm_recording::view`]
//!   module, the same bytes a recording's Foxglove views hold ([`encoding`]).
//! - **Foxglove's time is valid time.** A message's log time is its structure's valid
//!   time, and the server broadcasts the latest valid time forwarded as its time.
//! - **Nothing flows unwatched.** The first subscriber of a channel opens the
//!   trajectory and subscribes to it ([`forward`]); the last one leaving stops the
//!   thread and drops the handle, so an unwatched image stream costs nothing here.
//! - **Traces too.** A produced trajectory also has a channel `/<trajectory>/trace`:
//!   each structure's inputs hop by hop, with the end-to-end latency and each stage's
//!   share, to plot where a pipeline's time goes ([`trace_view`]).
//! - **Both names of the protocol.** The spec's clients (Lichtblick, older Foxglove
//!   Studio, `@foxglove/ws-protocol`) ask for `foxglove.websocket.v1`, the SDK's server
//!   knows the same protocol as `foxglove.sdk.v1`: a front door translates the name in
//!   the handshake and relays the rest ([`door`]).
#![deny(missing_docs)]

pub mod door;
pub mod encoding;
pub mod forward;
pub mod server;
pub mod trace_view;

pub use server::{ViewServer, ViewServerBuilder};
