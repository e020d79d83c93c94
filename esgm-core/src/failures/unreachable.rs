//! Why a part of the ESGM in another process could not be reached: the typed cause of
//! every `Unavailable` error (CORBA's `COMM_FAILURE`), so that a caller can decide what
//! to do (start a coordinator, retry, wait for a restart, report a bug) without
//! parsing a message.

/// The party that could not be reached or answered wrongly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum Peer {
    /// The domain's coordinator (the registry of names).
    Coordinator,
    /// The process that writes the trajectory.
    Writer,
    /// Other processes that hold the trajectory or serve the system (a reset, a flush,
    /// statistics gathered from every process).
    Processes,
    /// This process's own connection (its location thread).
    Connection,
}

impl std::fmt::Display for Peer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Coordinator => "the coordinator",
            Self::Writer => "the writer",
            Self::Processes => "the other processes",
            Self::Connection => "this process's connection",
        })
    }
}

/// Why the ESGM, or a process of it, could not be reached or did not answer. Each
/// variant says what the caller can do; transport details (which `esgm-core` does not
/// name) are kept as text in `detail`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum Unreachable {
    /// No coordinator serves the domain: start one (`esgm up`), or connect to the
    /// right domain.
    #[error("no coordinator serves domain `{domain}`; start one with `esgm up`")]
    NoCoordinator {
        /// The domain.
        domain: String,
    },
    /// `peer` did not answer in time: it is overloaded, stuck or gone. Retry, or look
    /// at it (`esgm ps`, `esgm logs`).
    #[error("{peer} did not answer within {timeout_ms} ms")]
    NoAnswer {
        /// Who did not answer.
        peer: Peer,
        /// How long it was waited for.
        timeout_ms: u64,
    },
    /// This process's connection is closing (the `ShmEsgm` is being dropped): nothing
    /// more goes through it.
    #[error("the connection is closing")]
    Closing,
    /// `peer` refused the request for a reason that is not one of the operation's own
    /// errors (a rule of the coordinator, a change it could not save).
    #[error("{peer} refused: {detail}")]
    Refused {
        /// Who refused.
        peer: Peer,
        /// Its words.
        detail: String,
    },
    /// `peer` answered with bytes that do not decode (another version of esgm, or a
    /// hostile process): nothing was taken from them.
    #[error("malformed answer from {peer}: {detail}")]
    Malformed {
        /// Who answered.
        peer: Peer,
        /// What did not decode.
        detail: String,
    },
    /// The shared-memory transport failed to reach `peer` (a port or service could not
    /// be opened or used): look at the transport's detail, and at the domain's limits.
    #[error("cannot reach {peer}: {detail}")]
    Transport {
        /// Who was to be reached.
        peer: Peer,
        /// The transport's words.
        detail: String,
    },
}

impl Unreachable {
    /// `peer` did not answer within `timeout`.
    pub fn no_answer(peer: Peer, timeout: std::time::Duration) -> Self {
        Self::NoAnswer { peer, timeout_ms: u64::try_from(timeout.as_millis()).unwrap_or(u64::MAX) }
    }

    /// The transport failed to reach `peer`, for the reason `detail`.
    pub fn transport(peer: Peer, detail: impl std::fmt::Display) -> Self {
        Self::Transport { peer, detail: detail.to_string() }
    }

    /// `peer` answered with something that does not decode.
    pub fn malformed(peer: Peer, detail: impl std::fmt::Display) -> Self {
        Self::Malformed { peer, detail: detail.to_string() }
    }

    /// `peer` refused, in its words.
    pub fn refused(peer: Peer, detail: impl std::fmt::Display) -> Self {
        Self::Refused { peer, detail: detail.to_string() }
    }
}
