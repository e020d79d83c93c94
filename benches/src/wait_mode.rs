//! How both processes of a cross-process ping-pong wait, and how that maps to rows.
//!
//! The report knows two waits ([`Wait`]: `spin`, `event`), fixed by the JSON contract.
//! Across processes esgm has three worth measuring: busy-spinning, blocking on the
//! iceoryx2 wake-up event, and its default, spinning briefly and then blocking
//! ([`esgm_shm::WaitStrategy::default`]). The third is an `event` row too — it blocks
//! when nothing comes — so its rows are told apart by **name**: scenario `esgm-small`
//! writes `esgm-small` (`spin`), `esgm-small` (`event`, pure blocking) and
//! `esgm-small-default` (`event`, the default strategy). Every cross-process row also
//! carries the exact strategy in the optional `wait_strategy` JSON field
//! ([`WaitMode::label`]). So `(name, wait)` stays a unique key, and the five names the
//! issue fixes mean what it says: `event` = blocking on an event.

use clap::ValueEnum;

use crate::report::Wait;

/// How both ends of a cross-process ping-pong wait for the next message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, ValueEnum)]
pub enum WaitMode {
    /// Busy-polling (iceoryx2 `receive` in a loop; a non-blocking socket read).
    Spin,
    /// Blocking until woken (the iceoryx2 event listener; a blocking socket read).
    Block,
    /// esgm's default: spin briefly, then block on the event.
    #[value(name = "default")]
    SpinThenBlock,
}

impl WaitMode {
    /// The two waits every transport has.
    pub const SPIN_AND_BLOCK: [WaitMode; 2] = [WaitMode::Spin, WaitMode::Block];
    /// The three waits of esgm's subscribers.
    pub const ESGM: [WaitMode; 3] = [WaitMode::Spin, WaitMode::Block, WaitMode::SpinThenBlock];

    /// The row's wait: `spin`, or `event` for anything that blocks.
    pub fn wait(self) -> Wait {
        match self {
            WaitMode::Spin => Wait::Spin,
            WaitMode::Block | WaitMode::SpinThenBlock => Wait::Event,
        }
    }

    /// The row's name for scenario `scenario`: `<scenario>-default` for the default
    /// strategy (see the module docs), the scenario's name otherwise.
    pub fn row_name(self, scenario: &str) -> String {
        match self {
            WaitMode::SpinThenBlock => format!("{scenario}-default"),
            WaitMode::Spin | WaitMode::Block => scenario.to_owned(),
        }
    }

    /// The command-line value (`spin`, `block`, `default`), as passed to a peer process.
    pub fn arg(self) -> &'static str {
        match self {
            WaitMode::Spin => "spin",
            WaitMode::Block => "block",
            WaitMode::SpinThenBlock => "default",
        }
    }

    /// The `wait_strategy` of a row.
    pub fn label(self) -> &'static str {
        match self {
            WaitMode::Spin => "busy-spin",
            WaitMode::Block => "block",
            WaitMode::SpinThenBlock => "spin-then-block",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_keep_name_and_wait_unique() {
        let rows: Vec<_> =
            WaitMode::ESGM.iter().map(|m| (m.row_name("esgm-small"), m.wait())).collect();
        assert_eq!(
            rows,
            [
                ("esgm-small".to_owned(), Wait::Spin),
                ("esgm-small".to_owned(), Wait::Event),
                ("esgm-small-default".to_owned(), Wait::Event),
            ]
        );
        for m in WaitMode::ESGM {
            assert_eq!(WaitMode::from_str(m.arg(), false), Ok(m));
        }
    }
}
