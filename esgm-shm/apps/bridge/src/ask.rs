//! Asking the exporters on Zenoh: one query, every reply (none consolidated away: a
//! history is many replies on one key).

use std::time::Duration;

use zenoh::Wait as _;
use zenoh::query::ConsolidationMode;

use crate::key::{ASK, Ask};
use crate::session::ZenohError;

/// One reply.
#[derive(Debug, Clone)]
pub struct Answer {
    /// The key it was sent on.
    pub key: String,
    /// Its payload.
    pub payload: Vec<u8>,
}

/// The replies and the error replies of a query.
#[derive(Debug, Default)]
pub struct Answers {
    /// Replies, in arrival order.
    pub ok: Vec<Answer>,
    /// Error replies (their text).
    pub errors: Vec<String>,
}

/// Asks `ask` with `params` (`name=value`) on `key`; waits at most `timeout`.
pub fn ask(
    session: &zenoh::Session,
    key: &str,
    ask: Ask,
    params: &[(&str, String)],
    timeout: Duration,
) -> Result<Answers, ZenohError> {
    let mut selector = format!("{key}?{ASK}={}", ask.as_str());
    for (name, value) in params {
        selector.push_str(&format!(";{name}={value}"));
    }
    let replies = session
        .get(selector)
        .consolidation(ConsolidationMode::None)
        .timeout(timeout)
        .wait()
        .map_err(ZenohError::from)?;
    let mut answers = Answers::default();
    // The channel closes when every queryable has answered or the timeout passed.
    while let Ok(reply) = replies.recv() {
        match reply.result() {
            Ok(sample) => answers.ok.push(Answer {
                key: sample.key_expr().as_str().to_owned(),
                payload: sample.payload().to_bytes().into_owned(),
            }),
            Err(e) => answers.errors.push(
                e.payload()
                    .try_to_string()
                    .map_or_else(|_| "(binary error)".into(), |s| s.into_owned()),
            ),
        }
    }
    Ok(answers)
}
