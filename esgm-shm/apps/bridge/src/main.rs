//! `esgm-bridge`: carries trajectories between the domains of several hosts over Zenoh
//! (see the crate docs of `esgm_bridge`). Usually run as `esgm bridge …`.

use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use esgm_bridge::export::{self, ExportOptions, ExportSite};
use esgm_bridge::import::{self, ImportSite};
use esgm_bridge::key;
use esgm_bridge::remote::{self, QueryArgs};
use esgm_bridge::serve::{self, ServeSite};
use esgm_bridge::session::ZenohArgs;
use esgm_bridge::stats::Stats;
use esgm_core::Esgm;
use esgm_shm::{CoordinatorWatch, ShmEsgm};

/// esgm-bridge — trajectories across hosts through Zenoh.
#[derive(Debug, Parser)]
#[command(name = "esgm-bridge", version, about)]
struct Cli {
    /// The local system (one coordinator per domain).
    #[arg(long, global = true, env = "ESGM_DOMAIN", default_value = "esgm")]
    domain: String,
    /// Print data as JSON.
    #[arg(long, global = true)]
    json: bool,
    #[command(flatten)]
    run: RunArgs,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Ask another host's bridge: latest, nth, between, at, closest.
    Query(QueryArgs),
}

/// Running a bridge.
#[derive(Debug, clap::Args)]
struct RunArgs {
    #[command(flatten)]
    zenoh: ZenohArgs,
    /// Export this trajectory of the local domain; repeatable.
    #[arg(long, value_name = "TRAJECTORY")]
    export: Vec<String>,
    /// Export every trajectory of the local domain (but those this bridge imports).
    #[arg(long)]
    all: bool,
    /// Import `<domain>/<trajectory>` (either may be `*`) or everything under a key
    /// expression (`esgm/<domain>/…`); repeatable.
    #[arg(long, value_name = "DOMAIN/TRAJECTORY")]
    import: Vec<String>,
    /// For this exported trajectory, send only the newest of the samples waiting
    /// (where the network is the bottleneck); skipped ones are counted. Repeatable.
    #[arg(long, value_name = "TRAJECTORY")]
    latest_only: Vec<String>,
    /// At most this rate for an exported trajectory: `images=5` (Hz); the newest
    /// sample waiting is sent, skipped ones are counted. Repeatable.
    #[arg(long, value_name = "TRAJECTORY=HZ")]
    max_rate: Vec<String>,
    /// Do not answer the seed's queries from other hosts (`esgm --remote`).
    #[arg(long)]
    no_queries: bool,
    /// Print every trajectory's counters as JSON lines this often (e.g. `1s`).
    #[arg(long, value_parser = humantime::parse_duration)]
    report_every: Option<Duration>,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    esgm_shm::process::init_logging();
    let result = match &cli.command {
        Some(Command::Query(q)) => remote::run(&cli.domain, cli.json, q),
        None => run(&cli.domain, &cli.run),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("esgm-bridge: {}", esgm_shm::process::one_line(e.chain()));
            ExitCode::FAILURE
        }
    }
}

fn export_options(a: &RunArgs, name: &str) -> anyhow::Result<ExportOptions> {
    let mut max_rate = None;
    for spec in &a.max_rate {
        let (n, hz) = spec
            .split_once('=')
            .with_context(|| format!("--max-rate `{spec}`: expected TRAJECTORY=HZ"))?;
        if n == name {
            let hz: f64 = hz.parse().with_context(|| format!("--max-rate `{spec}`: HZ"))?;
            esgm_core::time::period_from_rate(hz)
                .with_context(|| format!("--max-rate `{spec}`: the rate"))?;
            max_rate = Some(hz);
        }
    }
    Ok(ExportOptions {
        name: name.to_owned(),
        latest_only: a.latest_only.iter().any(|n| n == name),
        max_rate,
    })
}

/// A number no other run of a bridge picks: what tells the importer this exporter
/// restarted.
fn session_id() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u32(std::process::id());
    h.write_u128(
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos()),
    );
    h.finish()
}

fn run(domain: &str, a: &RunArgs) -> anyhow::Result<()> {
    anyhow::ensure!(key::is_name(domain), "domain `{domain}` cannot name a Zenoh key");
    for name in a.export.iter().chain(&a.latest_only) {
        anyhow::ensure!(key::is_name(name), "trajectory `{name}` cannot name a Zenoh key");
    }
    let imports: Vec<String> = a
        .import
        .iter()
        .map(|s| key::import_key(s).map_err(anyhow::Error::msg))
        .collect::<anyhow::Result<_>>()?;
    let esgm = ShmEsgm::builder()
        .domain(domain)
        .host(format!("esgm-bridge-{}", std::process::id()))
        .connect()
        .with_context(|| format!("cannot reach the system `{domain}`"))?;
    // The bridge writes the trajectories it imports.
    esgm.serve_assignments();
    let session = a.zenoh.open()?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
            .context("installing the Ctrl-C/SIGTERM handler")?;
    }
    let stats = Stats::default();
    let session_id = session_id();
    let catalog = export::Catalog::default();
    let mut threads = Vec::new();
    threads.push(serve::spawn(ServeSite {
        domain: domain.to_owned(),
        esgm: esgm.clone(),
        session: session.clone(),
        session_id,
        catalog: Arc::clone(&catalog),
        queries: !a.no_queries,
        stop: Arc::clone(&stop),
    })?);
    let export_site = ExportSite {
        domain: domain.to_owned(),
        esgm: esgm.clone(),
        session: session.clone(),
        session_id,
        catalog,
        stats: stats.clone(),
        stop: Arc::clone(&stop),
    };
    let mut exported = std::collections::BTreeSet::new();
    for name in &a.export {
        if exported.insert(name.clone()) {
            threads.push(export::spawn(export_site.clone(), export_options(a, name)?)?);
        }
    }
    for k in &imports {
        threads.push(import::spawn(
            ImportSite {
                domain: domain.to_owned(),
                esgm: esgm.clone(),
                session: session.clone(),
                stats: stats.clone(),
                stop: Arc::clone(&stop),
            },
            k.clone(),
        )?);
    }
    println!(
        "esgm-bridge: domain `{domain}`, zenoh {}: exporting {}, importing {}",
        session.zid(),
        if a.all { "all".to_owned() } else { format!("{:?}", a.export) },
        format_args!("{imports:?}"),
    );
    let mut reported = Instant::now();
    let mut last_listing = Instant::now();
    // It leaves with its system: 3 s without the coordinator's answer.
    let mut coordinator = CoordinatorWatch::new(Duration::from_secs(3));
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(50));
        if a.all && last_listing.elapsed() >= Duration::from_millis(500) {
            last_listing = Instant::now();
            // A listing the coordinator did not give is tried again at the next round.
            let listed = esgm.trajectories().unwrap_or_else(|e| {
                tracing::debug!(error = %e, "cannot list the trajectories to export now");
                Vec::new()
            });
            for info in listed {
                if exported.contains(&info.name) || !key::is_name(&info.name) {
                    continue;
                }
                // Never send back what this bridge imports (or another bridge here).
                match export::lookup(&esgm, &info.name) {
                    Ok(r) if r.writer.starts_with("esgm-bridge-") => continue,
                    Ok(_) => {}
                    // Asked again on the next pass; said, so one never exported is seen.
                    Err(e) => {
                        tracing::debug!(trajectory = %info.name, error = %e,
                            "cannot look up a trajectory to export now");
                        continue;
                    }
                }
                exported.insert(info.name.clone());
                threads.push(export::spawn(export_site.clone(), export_options(a, &info.name)?)?);
            }
        }
        if coordinator.gone(&esgm) {
            stop.store(true, Ordering::Relaxed);
            eprintln!("esgm-bridge: the coordinator of `{domain}` is gone; stopping");
        }
        if let Some(every) = a.report_every {
            if reported.elapsed() >= every {
                reported = Instant::now();
                report(&stats);
            }
        }
    }
    stop.store(true, Ordering::Relaxed);
    for t in threads {
        if t.join().is_err() {
            tracing::error!("a bridge thread panicked");
        }
    }
    report(&stats);
    Ok(())
}

fn report(stats: &Stats) {
    esgm_shm::process::print_json_lines(stats.snapshot());
}
