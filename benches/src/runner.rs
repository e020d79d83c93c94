//! Runs the selected scenarios, in order, into a [`Report`].

use std::io::Write;
use std::time::Instant;

use anyhow::{Context as _, bail};

use crate::config::RunConfig;
use crate::peer_role::PeerRole;
use crate::pin::pin_to_core;
use crate::report::Report;
use crate::scenario::{Context, Scenario};

/// The scenarios of `all` whose name contains `only`, or one of its comma-separated
/// parts (all of them without a filter), in run order.
pub fn select<'a>(all: &'a [Box<dyn Scenario>], only: Option<&str>) -> Vec<&'a dyn Scenario> {
    let matches = |name: &str| {
        only.is_none_or(|o| o.split(',').any(|part| !part.is_empty() && name.contains(part)))
    };
    all.iter().map(AsRef::as_ref).filter(|s| matches(s.name())).collect()
}

/// Runs the scenarios of `all` that `config` selects, telling `progress` what it is
/// doing. Stops at the first scenario that fails.
pub fn run(
    config: &RunConfig,
    all: &[Box<dyn Scenario>],
    progress: &mut dyn Write,
) -> anyhow::Result<Report> {
    let selected = select(all, config.only.as_deref());
    if selected.is_empty() {
        let names: Vec<_> = all.iter().map(|s| s.name()).collect();
        bail!(
            "--only {:?} matches no scenario; the scenarios are: {}",
            config.only.as_deref().unwrap_or(""),
            names.join(", ")
        );
    }
    if let Some(p) = config.pin {
        p.pin_measuring_thread().context("--pin")?;
    }
    // Held until the last scenario ends.
    let _held = config
        .cpu_latency
        .map(esgm_shm::process::cpu_latency::CpuLatency::request)
        .transpose()
        .context("--cpu-latency")?;
    let ctx = Context::new(config);
    let mut report = Report { machine: crate::report::Machine::now(), ..Report::default() };
    let (total, run_started) = (selected.len(), Instant::now());
    for (done, scenario) in selected.into_iter().enumerate() {
        // Progress lines are a courtesy; a closed stderr must not stop the run.
        let _ = write!(progress, "[{}/{total}] {:<26} ", done + 1, scenario.name());
        let _ = progress.flush();
        let started = Instant::now();
        let rows =
            scenario.run(&ctx).with_context(|| format!("scenario {} failed", scenario.name()))?;
        let eta = eta(run_started.elapsed(), done + 1, total);
        let _ = writeln!(progress, "{:>6.1} s{eta}", started.elapsed().as_secs_f64());
        report.add_rows(rows);
        report.memory.extend(ctx.take_memory());
        report.skipped.extend(ctx.take_skipped());
        report.targets.extend(scenario.targets());
    }
    Ok(report)
}

/// `  (ETA 1m 20s)`: the time left if the remaining scenarios take as long as the
/// finished ones did on average; empty after the last one.
fn eta(elapsed: std::time::Duration, done: usize, total: usize) -> String {
    if done == 0 || done >= total {
        return String::new();
    }
    let left = elapsed.as_secs_f64() / done as f64 * (total - done) as f64;
    let secs = left.round() as u64;
    if secs >= 60 {
        format!("  (ETA {}m {:02}s)", secs / 60, secs % 60)
    } else {
        format!("  (ETA {secs}s)")
    }
}

/// Runs as the peer process `role` describes (see [`crate::peer_role`]): the peer side
/// of the scenario it names, pinned to its core if given one. Returns the notes the
/// peer has for the report.
pub fn run_peer(role: &PeerRole, all: &[Box<dyn Scenario>]) -> anyhow::Result<Vec<String>> {
    let Some(scenario) = all.iter().find(|s| s.name() == role.scenario) else {
        bail!("--peer {:?} names no scenario", role.scenario);
    };
    if let Some(core) = role.core {
        pin_to_core(core).context("--peer-core")?;
    }
    scenario
        .run_peer(role)
        .with_context(|| format!("peer of {} ({})", role.scenario, role.wait.arg()))
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::eta;

    #[test]
    fn eta_is_the_average_so_far_times_what_is_left() {
        assert_eq!(eta(Duration::from_secs(30), 1, 3), "  (ETA 1m 00s)");
        assert_eq!(eta(Duration::from_secs(10), 2, 3), "  (ETA 5s)");
        assert_eq!(eta(Duration::from_secs(10), 3, 3), "");
    }
}
