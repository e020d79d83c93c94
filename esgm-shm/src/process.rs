//! What every esgm process's `main` does the same way: its logging, and its errors
//! on one line.
//!
//! The `esgm` command, the publishers and a user's unit executable are separate
//! programs of one system: they log alike (to stderr, `RUST_LOG` or warnings,
//! iceoryx2's own log cut to errors, since its warnings — no config file, defaults
//! used — are not news) and report a failure alike (one line naming what was wrong,
//! never a backtrace; STYLE habit 6).

/// Sets up the process's logging: `tracing` to stderr filtered by `RUST_LOG` (default
/// `warn`), iceoryx2's log at errors. Call once, first thing in `main`.
pub fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).init();
    iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Error);
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
