//! `esgm-fuzz`: fuzzes everything esgm decodes from another process (see the library
//! docs). Exit code 0: no finding; 1: findings (each input saved under `--findings`);
//! 2: the run itself failed.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use clap::Parser;
use esgm_fuzz::report::Report;
use esgm_fuzz::runner::{self, Cases};
use esgm_fuzz::supervise::{self, Plan};
use esgm_fuzz::targets::{self, NAMES};

/// Fuzzes the codec, the sample header, the control protocol, the admin channel,
/// blocking adds, the bridge's wire messages, recordings and the configuration parser
/// with mutated and random inputs; reports cases per second and findings. Build it
/// with `cargo build --profile fuzz -p esgm-fuzz` (release with overflow checks).
#[derive(Debug, Parser)]
#[command(name = "esgm-fuzz", version)]
struct Args {
    /// Total seconds to run, split evenly over the targets.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Seed of the run (default: from the clock; printed, so a run can be repeated).
    #[arg(long)]
    seed: Option<u64>,
    /// Fuzz only this target (repeatable); default: all.
    #[arg(long = "target", value_parser = NAMES)]
    targets: Vec<String>,
    /// Where failing inputs are saved (created on the first finding).
    #[arg(long, default_value = "fuzz-findings")]
    findings: PathBuf,
    /// One case running longer than this many milliseconds is a hang.
    #[arg(long, default_value_t = 1000)]
    hang_ms: u64,
    /// Run this saved input once against the one `--target` and say what happened.
    #[arg(long, value_name = "FILE")]
    input: Option<PathBuf>,
    /// List the targets and what each runs.
    #[arg(long)]
    list: bool,
    /// Start at this case index (with --seed and --max-cases: make a case again).
    #[arg(long, default_value_t = 0)]
    from: u64,
    /// Stop after this many cases (runs in this process, without a child).
    #[arg(long)]
    max_cases: Option<u64>,
    /// Run as the child of a fuzzing run (internal).
    #[arg(long, hide = true)]
    child: bool,
    /// Name every case before running it (internal).
    #[arg(long, hide = true)]
    trace: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    match run(args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("esgm-fuzz: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn one_target(args: &Args) -> anyhow::Result<Arc<dyn esgm_fuzz::target::Target>> {
    let [name] = &args.targets[..] else { anyhow::bail!("give exactly one --target") };
    let target = targets::by_name(name).with_context(|| format!("unknown target {name}"))?;
    let target = target.map_err(|e| anyhow::anyhow!("the {name} target's seeds fail: {e}"))?;
    Ok(Arc::from(target))
}

fn run(args: Args) -> anyhow::Result<ExitCode> {
    if args.list {
        for name in NAMES {
            let about = match targets::by_name(name) {
                Some(Ok(t)) => t.about().to_owned(),
                Some(Err(e)) => format!("(its seeds fail: {e})"),
                None => String::new(),
            };
            println!("{name:<10} {about}");
        }
        return Ok(ExitCode::SUCCESS);
    }
    let seed = args.seed.unwrap_or_else(clock_seed);
    let hang = Duration::from_millis(args.hang_ms);
    if let Some(file) = &args.input {
        let target = one_target(&args)?;
        let input =
            std::fs::read(file).with_context(|| format!("cannot read {}", file.display()))?;
        return Ok(match target.run(&input) {
            Ok(()) => {
                println!("{}: survived", file.display());
                ExitCode::SUCCESS
            }
            Err(broken) => {
                println!("{}: {broken}", file.display());
                ExitCode::FAILURE
            }
        });
    }
    if args.child || args.max_cases.is_some() {
        let target = one_target(&args)?;
        let cases = Cases {
            seed,
            from: args.from,
            budget: Duration::from_secs_f64(args.seconds.max(0.0)),
            max_cases: args.max_cases,
            hang,
            findings: args.findings.clone(),
            trace: args.trace,
            check_seeds: args.from == 0 && !args.trace,
        };
        let found = runner::run(target, cases);
        // A child's findings are the parent's to judge; a case run by hand fails here.
        return Ok(if found > 0 && !args.child { ExitCode::FAILURE } else { ExitCode::SUCCESS });
    }
    let plan = Plan {
        seconds: args.seconds.max(0.0),
        seed,
        targets: if args.targets.is_empty() {
            NAMES.iter().map(|n| (*n).to_owned()).collect()
        } else {
            args.targets.clone()
        },
        findings: args.findings.clone(),
        hang,
    };
    let exe = std::env::current_exe().context("cannot find this executable")?;
    let targets = supervise::run(&exe, &plan)?;
    let report = Report { plan, targets };
    print!("{report}");
    Ok(if report.findings() == 0 { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}

/// A seed from the clock, for runs that do not name one.
fn clock_seed() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}
