//! esgm-bench's dora peer: one node binary with two roles, chosen by
//! `ESGM_DORA_ROLE`, in a two-node dataflow that esgm-bench writes and runs with
//! `dora run`.
//!
//! - `pong` answers every message on its input `ping` with one of the same length on
//!   its output `out`, carrying the same sequence number.
//! - `ping` sends `ESGM_DORA_BYTES`-byte messages on `out` and times, on its monotonic
//!   clock, half of each round trip: from the moment the payload is complete in dora's
//!   output sample (written inside `send_output_raw`'s closure, so in dora's shared
//!   memory for large messages, the write itself untimed as in `esgm-image`) until the
//!   answer was received and its sequence number and last byte read. It writes one line
//!   `r <ns>` per measured hop to the file `ESGM_DORA_OUT`, the format of the ROS 1
//!   peer's output.
//!
//! `ESGM_DORA_WAIT` is `spin` (poll the event stream with `try_recv`) or `block`
//! (`recv_timeout`, with a 50 µs gap before each hop so that the other side sleeps).
//! `ESGM_DORA_CORE`, when set, pins the process (and so every thread dora starts in
//! it) to that core. Every wait has a deadline: a node that hears nothing exits with
//! status 2 and a line on stderr.

mod config;
mod inbox;
mod message;
mod ping;
mod pong;

use std::process::ExitCode;

fn main() -> ExitCode {
    let result = config::Config::from_env().and_then(|config| {
        config.pin()?;
        match config.role {
            config::Role::Ping => ping::run(&config),
            config::Role::Pong => pong::run(&config),
        }
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("esgm-dora-pingpong: {e}");
            ExitCode::from(2)
        }
    }
}
