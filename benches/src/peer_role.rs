//! What a peer process of a cross-process scenario is told to do.
//!
//! A cross-process scenario measures against a second process: `esgm-bench` starts
//! itself again with the hidden options `--peer <SCENARIO> --peer-wait <WAIT>
//! --peer-domain <DOMAIN> [--peer-core <CORE>]` ([`crate::peer_process::PeerProcess`]).
//! The peer finds the scenario by name and runs its [`crate::Scenario::run_peer`], which
//! echoes until told to stop. Whatever it wants in the report (notes) it prints on
//! stdout, one line each; errors go to stderr and a non-zero exit status.

use std::ffi::OsString;

use crate::wait_mode::WaitMode;

/// The role of a peer process (see the module docs).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PeerRole {
    /// The scenario whose peer side to run (its exact name).
    pub scenario: String,
    /// How the peer waits for each message.
    pub wait: WaitMode,
    /// Where the two processes meet: the esgm / iceoryx2 domain of the services, and
    /// the name of the Unix socket. Unique per measurement (it holds the measuring
    /// process's id).
    pub domain: String,
    /// The core to pin the peer to, under `--pin`. Passed explicitly because a child
    /// inherits the affinity of the (pinned) thread that started it, and so could not
    /// find the second core by itself.
    pub core: Option<usize>,
    /// What this peer is among several of one measurement (`coordinator`, a unit's
    /// name, a subscriber's index), for scenarios that start more than one kind.
    pub arg: Option<String>,
}

impl PeerRole {
    /// The command-line arguments that make `esgm-bench` this peer.
    pub fn to_args(&self) -> Vec<OsString> {
        let mut args: Vec<OsString> = vec![
            "--peer".into(),
            self.scenario.clone().into(),
            "--peer-wait".into(),
            self.wait.arg().into(),
            "--peer-domain".into(),
            self.domain.clone().into(),
        ];
        if let Some(core) = self.core {
            args.push("--peer-core".into());
            args.push(core.to_string().into());
        }
        if let Some(arg) = &self.arg {
            args.push("--peer-arg".into());
            args.push(arg.clone().into());
        }
        args
    }
}
