//! A hop's steps as the processes of a scenario saw them (`--features hop-probe`): each
//! esgm process prints its [`esgm_core::probe`] figures when it leaves, one line a step
//! ([`lines`]), and the measuring process joins the writer's and the reader's lines of
//! one hop into a note ([`note`]).

use esgm_core::probe::{self, Step};

/// What a step line begins with.
const PREFIX: &str = "step";

/// This process's steps as lines for the measuring process:
/// `step <process> <step> <n> <p50 ns> <p99 ns>`; none without the probes.
pub fn lines(process: &str) -> Vec<String> {
    probe::report()
        .into_iter()
        .map(|f| format!("{PREFIX} {process} {} {} {} {}", f.step.name(), f.n, f.p50, f.p99))
        .collect()
}

/// The steps `process` printed, in order: (step, p50, p99).
fn steps_of<'a>(process: &str, lines: &'a [String]) -> Vec<(&'a str, f64, f64)> {
    lines
        .iter()
        .filter_map(|line| {
            let mut w = line.split_whitespace();
            if w.next() != Some(PREFIX) || w.next() != Some(process) {
                return None;
            }
            let step = w.next()?;
            let _n: u64 = w.next()?.parse().ok()?;
            let p50: f64 = w.next()?.parse().ok()?;
            let p99: f64 = w.next()?.parse().ok()?;
            Some((step, p50, p99))
        })
        .collect()
}

/// A hop's steps, µs after the structure's add at p50 (p99), from the writer's
/// process's writer steps and the reader's process's reader steps; `None` if neither
/// printed any (a build without the probes).
pub fn note(writer: &str, reader: &str, lines: &[String]) -> Option<String> {
    let writes = Step::ALL[..7].iter().map(|s| s.name()).collect::<Vec<_>>();
    let mut parts = Vec::new();
    for (process, wanted) in [(writer, true), (reader, false)] {
        for (step, p50, p99) in steps_of(process, lines) {
            if writes.contains(&step) == wanted {
                parts.push(format!("{step} {:.1} ({:.1})", p50 / 1e3, p99 / 1e3));
            }
        }
    }
    (!parts.is_empty()).then(|| {
        format!(
            "steps, µs after the input's add at p50 (p99), writer `{writer}` then reader \
             `{reader}`: {}",
            parts.join(", ")
        )
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, reason = "a failure is a failed test")]
mod tests {
    use super::*;

    #[test]
    fn a_hop_note_joins_the_writers_and_the_readers_steps() {
        let lines: Vec<String> = [
            "step camera sent 10 2000 4000",
            "step camera woken 3 100 200",
            "step unit woken 10 9000 20000",
            "step unit sent 10 99 99",
            "woken unit 10 1 2",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let joined = note("camera", "unit", &lines).unwrap();
        assert!(joined.contains("sent 2.0 (4.0), woken 9.0 (20.0)"), "{joined}");
        assert!(note("a", "b", &lines).is_none());
    }
}
