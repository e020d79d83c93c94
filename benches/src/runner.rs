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
    let ctx = Context::new(config);
    let mut report = Report::default();
    for scenario in selected {
        // Progress lines are a courtesy; a closed stderr must not stop the run.
        let _ = write!(progress, "{:<26} ", scenario.name());
        let _ = progress.flush();
        let started = Instant::now();
        let rows =
            scenario.run(&ctx).with_context(|| format!("scenario {} failed", scenario.name()))?;
        let _ = writeln!(progress, "{:>6.1} s", started.elapsed().as_secs_f64());
        report.add_rows(rows);
        report.memory.extend(ctx.take_memory());
        report.skipped.extend(ctx.take_skipped());
        report.targets.extend(scenario.targets());
    }
    Ok(report)
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
