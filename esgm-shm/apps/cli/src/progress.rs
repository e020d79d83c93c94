//! Progress on the terminal for commands that take long (`record`, `replay`, `apply`),
//! drawn on stderr with `indicatif`.
//!
//! A bar is shown only to a person: with `--json`, or when stdout or stderr is not a
//! terminal (a pipe, a file, a test), every bar here is hidden and costs nothing, so
//! what scripts read is unchanged.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use esgm_core::Time;
use esgm_recording::{RecorderStats, ReplayPosition};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// True when a bar may be drawn.
fn interactive(json: bool) -> bool {
    !json && std::io::stdout().is_terminal() && std::io::stderr().is_terminal()
}

fn new_bar(json: bool, len: Option<u64>) -> ProgressBar {
    if !interactive(json) {
        return ProgressBar::hidden();
    }
    let bar = match len {
        Some(n) => ProgressBar::new(n),
        None => ProgressBar::new_spinner(),
    };
    bar.set_draw_target(ProgressDrawTarget::stderr_with_hz(4));
    bar
}

fn style(template: &str) -> ProgressStyle {
    // The templates are constants of this file: a bad one is a bug caught by the tests.
    ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar())
}

/// `esgm record`: structures and bytes written, the rate, what was missed.
#[derive(Debug)]
pub struct RecordProgress {
    bar: ProgressBar,
    file: PathBuf,
    last: Option<(Instant, u64)>,
    rate: f64,
}

impl RecordProgress {
    /// A spinner for a recording into `file`.
    pub fn start(json: bool, file: &Path) -> Self {
        let bar = new_bar(json, None);
        bar.set_style(style("{spinner} {elapsed_precise} {msg}"));
        Self { bar, file: file.to_path_buf(), last: None, rate: 0.0 }
    }

    /// Updates the line from `stats` (called only about four times a second: the
    /// recorder's statistics are copied under its lock).
    pub fn tick(&mut self, stats: impl FnOnce() -> RecorderStats) {
        if self.bar.is_hidden() {
            return;
        }
        let now = Instant::now();
        if self.last.is_some_and(|(t, _)| now - t < Duration::from_millis(250)) {
            return;
        }
        let stats = stats();
        let recorded = stats.recorded();
        if let Some((t, n)) = self.last {
            let dt = (now - t).as_secs_f64();
            if dt > 0.0 {
                self.rate = recorded.saturating_sub(n) as f64 / dt;
            }
        }
        self.last = Some((now, recorded));
        // The first file's size: with --split-* the later files are not counted here.
        let bytes = std::fs::metadata(&self.file).map_or(0, |m| m.len());
        self.bar.set_message(format!(
            "{recorded} structures, {}, {:.0}/s, {} missed",
            crate::dashboard::table::bytes(bytes),
            self.rate,
            stats.missed()
        ));
        self.bar.tick();
    }

    /// Removes the line (the summary follows).
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// `esgm replay`: the position in the recording's valid time, as the replay reports
/// it after every structure ([`ReplayPosition`]).
#[derive(Debug)]
pub struct ReplayProgress {
    bar: ProgressBar,
}

impl ReplayProgress {
    /// A bar over `span` (the valid times replayed, first to last), following
    /// `position`.
    pub fn start(json: bool, span: Option<(Time, Time)>, position: Arc<ReplayPosition>) -> Self {
        let length_ms = span.map(|(a, b)| u64::try_from((b - a) / 1_000_000).unwrap_or(0));
        let bar = match length_ms {
            Some(ms) if ms > 0 => {
                let bar = new_bar(json, Some(ms));
                bar.set_style(style("{elapsed_precise} [{bar:30}] {msg} (ETA {eta})"));
                bar
            }
            _ => {
                let bar = new_bar(json, None);
                bar.set_style(style("{spinner} {elapsed_precise} replaying {msg}"));
                bar
            }
        };
        if !bar.is_hidden() {
            let ticker = bar.clone();
            let first = span.map_or(0, |s| s.0);
            std::thread::spawn(move || {
                while !ticker.is_finished() {
                    let at = position.valid_time().map_or(0, |t| (t - first).max(0) / 1_000_000);
                    let pass = match position.passes() {
                        0 | 1 => String::new(),
                        n => format!(", pass {n}"),
                    };
                    let done = format!("{} structures{pass}", position.published());
                    match ticker.length() {
                        Some(len) => {
                            let pos = (at as u64).min(len);
                            ticker.set_position(pos);
                            ticker.set_message(format!(
                                "{:.1} of {:.1} s, {done}",
                                pos as f64 / 1000.0,
                                len as f64 / 1000.0
                            ));
                        }
                        None => {
                            ticker.set_message(done);
                            ticker.tick();
                        }
                    }
                    std::thread::sleep(Duration::from_millis(250));
                }
            });
        }
        Self { bar }
    }

    /// Removes the bar.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// `esgm apply`: items of the file applied, of all.
#[derive(Debug)]
pub struct ApplyProgress {
    bar: ProgressBar,
}

impl ApplyProgress {
    /// A bar over `items` declarations.
    pub fn start(json: bool, items: usize) -> Self {
        let bar = new_bar(json, Some(items as u64));
        bar.set_style(style("{elapsed_precise} [{bar:30}] {pos}/{len} applied {msg}"));
        Self { bar }
    }

    /// Prints `line` above the bar and counts one item.
    pub fn println(&self, line: &str) {
        self.bar.suspend(|| println!("{line}"));
        self.bar.inc(1);
    }

    /// Removes the bar.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bars_are_hidden_for_json_and_off_a_terminal() {
        // Under `cargo test` stdout is captured: not a terminal.
        assert!(RecordProgress::start(false, Path::new("x")).bar.is_hidden());
        let position = Arc::new(ReplayPosition::default());
        assert!(ReplayProgress::start(true, Some((0, 1_000_000_000)), position).bar.is_hidden());
        let apply = ApplyProgress::start(true, 3);
        assert!(apply.bar.is_hidden());
        apply.finish();
    }

    #[test]
    fn templates_parse() {
        for t in [
            "{spinner} {elapsed_precise} {msg}",
            "{elapsed_precise} [{bar:30}] {msg} (by the clock; ETA {eta})",
            "{spinner} {elapsed_precise} replaying {msg}",
            "{elapsed_precise} [{bar:30}] {pos}/{len} applied {msg}",
        ] {
            assert!(ProgressStyle::with_template(t).is_ok(), "{t}");
        }
    }
}
