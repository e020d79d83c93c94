//! The answering node.

use std::time::Duration;

use dora_node_api::{DoraNode, MetadataParameters, dora_core::config::DataId};

use crate::config::Config;
use crate::inbox::{self, Got};
use crate::message;

/// How long pong waits for the next ping: ping's own deadline plus its start-up.
const TIMEOUT: Duration = Duration::from_secs(60);

/// Answers each ping with a message of the same length and sequence number until
/// [`message::STOP`] or the end of the dataflow.
///
/// The answer is a fresh output sample with its sequence number and last byte written,
/// not a copy of the 921,600 received bytes: in `esgm-image` the answering process's
/// frame is written before its hop, untimed, and dora cannot send a received sample
/// back on without copying it into a new one.
pub fn run(config: &Config) -> Result<(), String> {
    let (mut node, mut events) =
        DoraNode::init_from_env_force().map_err(|e| format!("starting the dora node: {e}"))?;
    let out = DataId::from("out".to_owned());
    loop {
        let (seq, len) = match inbox::next(&mut events, config.wait, TIMEOUT)? {
            Got::Message { seq, len } => (seq, len),
            Got::Closed => return Ok(()),
        };
        if seq == message::STOP {
            return Ok(());
        }
        node.send_output_raw(out.clone(), MetadataParameters::default(), len, |payload| {
            message::stamp(payload, seq)
        })
        .map_err(|e| format!("answering {seq}: {e}"))?;
    }
}
