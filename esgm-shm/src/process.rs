//! What every esgm process's `main` does the same way: its logging, and its errors
//! on one line.
//!
//! The `esgm` command, the publishers and a user's unit executable are separate
//! programs of one system: they log alike (to stderr, `RUST_LOG` or warnings,
//! iceoryx2's own log cut to errors, since its warnings — no config file, defaults
//! used — are not news) and report a failure alike (one line naming what was wrong,
//! never a backtrace; ARCHITECTURE.md, "Code habits that matter"). They also share their domain's shared memory
//! alike: privately unless the domain was started to allow others ([`share_domain`]).

pub mod access;
pub mod cpu_latency;

use std::sync::OnceLock;

use esgm_core::esgm::LogLevel;

/// Replaces the process's log filter (installed by [`init_logging`]).
type SetFilter = Box<dyn Fn(&str) -> Result<(), LogFilterError> + Send + Sync>;

/// The process's log filter could not be replaced ([`apply_log_level`]).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LogFilterError {
    /// The level's directive did not parse (a bug: esgm makes it).
    #[error("the log filter `{directive}` does not parse: {source}")]
    Parse {
        /// The directive.
        directive: String,
        /// Why.
        source: tracing_subscriber::filter::ParseError,
    },
    /// The running subscriber is gone (the process is exiting).
    #[error("cannot replace the log filter: {0}")]
    Reload(#[from] tracing_subscriber::reload::Error),
}

/// The running filter's reload handle, once [`init_logging`] installed it.
static LOG_FILTER: OnceLock<SetFilter> = OnceLock::new();

/// Sets up the process's logging: `tracing` to stderr filtered by `RUST_LOG` (default
/// `warn`), iceoryx2's log at errors. Call once, first thing in `main`. The filter can
/// be replaced while the process runs ([`apply_log_level`]; `esgm log-level`, or
/// `set_log_level` from any process of the system, reaches it).
pub fn init_logging() {
    init_logging_with("warn");
}

/// [`init_logging`] with `default` as the filter when `RUST_LOG` is unset: a program
/// quiets a dependency's warnings that are not news for it (e.g. `esgm-ros2` needs no
/// ROS installation, so `ros2-client`'s "ROS_DISTRO is not set" is not one).
pub fn init_logging_with(default: &str) {
    use tracing_subscriber::layer::SubscriberExt as _;
    use tracing_subscriber::util::SubscriberInitExt as _;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .or_else(|_| tracing_subscriber::EnvFilter::try_new(default))
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    let (filter, handle) = tracing_subscriber::reload::Layer::new(filter);
    tracing_subscriber::registry()
        .with(filter)
        .with(tracing_subscriber::fmt::layer().with_writer(std::io::stderr))
        .init();
    let set: SetFilter = Box::new(move |directives: &str| {
        let filter = tracing_subscriber::EnvFilter::try_new(directives)
            .map_err(|source| LogFilterError::Parse { directive: directives.to_owned(), source })?;
        Ok(handle.reload(filter)?)
    });
    if LOG_FILTER.set(set).is_err() {
        tracing::warn!("init_logging called twice; the first filter stays reloadable");
    }
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
}

/// Opens this process's files of `domain` to the users [`access::ACCESS_ENV`] admits,
/// for as long as the returned [`access::Widener`] lives; `None` when the domain is
/// private (the default: iceoryx2's files are its owner's alone, and nothing needs
/// doing). The coordinator sets the variable on every worker it starts, so a domain
/// started with `esgm up --allow-group` or `--allow-others` stays open while its
/// workers run; a second user's process sets it to publish into such a domain.
///
/// A library user's program (`esgm_shm::connect`) is not changed behind its back: it
/// calls this itself, or [`access::Widener::start`] with the access it chooses.
pub fn share_domain(domain: &str) -> Result<Option<access::Widener>, access::AccessError> {
    access::Widener::start(domain, access::ShmAccess::from_env()?)
}

/// Makes `level` this process's log filter (every target at that level), if
/// [`init_logging`] installed a reloadable one: `Ok(true)` once applied, `Ok(false)`
/// for a process whose logging is its own (a library user's subscriber; it reads the
/// level from `Esgm::log_level`).
pub fn apply_log_level(level: LogLevel) -> Result<bool, LogFilterError> {
    let Some(set) = LOG_FILTER.get() else { return Ok(false) };
    set(level_directive(level)).map(|()| true)
}

/// The filter directive of a level.
pub fn level_directive(level: LogLevel) -> &'static str {
    match level {
        LogLevel::Error => "error",
        LogLevel::Warn => "warn",
        LogLevel::Info => "info",
        LogLevel::Debug => "debug",
        LogLevel::Trace => "trace",
    }
}

/// An error and its causes on one line (`anyhow::Error::chain()`, or any error's
/// sources), leaving out a cause the line already says: some errors repeat their
/// source in their own message.
pub fn one_line<'a>(
    chain: impl IntoIterator<Item = &'a (dyn std::error::Error + 'static)>,
) -> String {
    chain.into_iter().map(ToString::to_string).fold(String::new(), |line, cause| {
        match line.as_str() {
            "" => cause,
            _ if line.contains(&cause) => line,
            _ => format!("{line}: {cause}"),
        }
    })
}

/// Prints `lines` to stdout as JSON lines, one object each, and flushes: a bridge's
/// per-topic report (`esgm-bridge`, `esgm-ros2`), read by people and by tests as it
/// comes. A closed stdout ends the report quietly.
pub fn print_json_lines<T: serde::Serialize>(lines: impl IntoIterator<Item = T>) {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    for item in lines {
        match serde_json::to_string(&item) {
            Ok(line) => {
                if writeln!(out, "{line}").is_err() {
                    return;
                }
            }
            Err(e) => tracing::warn!(error = %e, "a report line cannot be printed"),
        }
    }
    if out.flush().is_err() {
        tracing::debug!("stdout closed");
    }
}

/// Removes the files a domain keeps in `/dev/shm` beside iceoryx2's services, at the
/// domain's end (`esgm down`, the end of `esgm up` and of `esgm demo`): the wake words
/// ([`crate::unstable::WakeWord`]), which a process killed while it mapped one
/// leaves counted, and the trajectories' kept histories
/// ([`crate::unstable::KeptHistory`]), which outlive every process while the domain
/// runs and not after. Returns how many files were removed.
pub fn remove_domain_files(domain: &str) -> usize {
    crate::data_plane::wake_word::remove_domain(domain)
        + crate::data_plane::kept::KeptHistory::remove_domain(domain)
}

/// True while process `pid` runs (a zombie has stopped).
pub(crate) fn process_alive(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Ok(stat) => {
            stat.rsplit_once(')').is_some_and(|(_, rest)| !rest.trim_start().starts_with('Z'))
        }
        // No stat to read: the process is gone.
        Err(_) => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("cannot connect: {0}")]
    struct Outer(#[source] Inner);

    #[derive(Debug, thiserror::Error)]
    #[error("no coordinator")]
    struct Inner;

    #[derive(Debug, thiserror::Error)]
    #[error("cannot start")]
    struct Start(#[source] Inner);

    fn chain<'a>(
        e: &'a (dyn std::error::Error + 'static),
    ) -> Vec<&'a (dyn std::error::Error + 'static)> {
        std::iter::successors(Some(e), |e| e.source()).collect()
    }

    #[test]
    fn causes_join_once() {
        assert_eq!(one_line(chain(&Start(Inner))), "cannot start: no coordinator");
        assert_eq!(one_line(chain(&Outer(Inner))), "cannot connect: no coordinator", "said once");
    }
}
