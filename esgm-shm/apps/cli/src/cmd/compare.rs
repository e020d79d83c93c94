//! `esgm compare A B`: two recordings aligned by valid time, trajectory by trajectory;
//! exits 1 when they differ.

use std::path::PathBuf;

use anyhow::{Context, bail};
use esgm_core::Time;
use esgm_recording::compare::InputComparison;
use esgm_recording::{Alignment, CompareOptions, CompareReport, Presence, Recording, compare};

/// `esgm compare` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The first recording.
    pub a: PathBuf,
    /// The second recording.
    pub b: PathBuf,
    /// Compare only these trajectories.
    #[arg(long, num_args = 1..)]
    pub only: Vec<String>,
    /// How structures are paired: `exact` valid times, or B's `nearest` valid time
    /// within a --tolerance duration.
    #[arg(long, value_enum, default_value = "exact")]
    pub approx: Rule,
    /// A duration (`5ms`: how far apart `--approx nearest` may pair) or a plain number
    /// (numbers within it are equal); may be given once of each kind.
    #[arg(long)]
    pub tolerance: Vec<String>,
    /// Do not compare create times (a replay with times shifted to now).
    #[arg(long)]
    pub ignore_create_time: bool,
    /// Compare each trajectory only over the valid times both files cover (a live
    /// recording against a rerun of its inputs).
    #[arg(long)]
    pub overlap: bool,
}

/// Alignment rules on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Rule {
    /// The same valid time.
    Exact,
    /// B's closest valid time, within the duration tolerance.
    Nearest,
}

/// The recordings differ: `main` exits 1 without an error line (the report said it).
#[derive(Debug, thiserror::Error)]
#[error("the recordings differ")]
pub struct Differ;

/// The validated options.
fn options(a: &Args) -> anyhow::Result<CompareOptions> {
    let (mut within, mut value): (Option<Time>, Option<f64>) = (None, None);
    for t in &a.tolerance {
        if let Ok(x) = t.parse::<f64>() {
            if value.replace(x).is_some() {
                bail!("--tolerance: two numeric tolerances given");
            }
            if x.is_nan() || x < 0.0 {
                bail!("--tolerance {t}: a numeric tolerance must be 0 or more");
            }
        } else {
            let d = humantime::parse_duration(t).with_context(|| {
                format!("--tolerance `{t}` is neither a number nor a duration like 5ms")
            })?;
            let ns = Time::try_from(d.as_nanos()).context("--tolerance: duration too large")?;
            if within.replace(ns).is_some() {
                bail!("--tolerance: two duration tolerances given");
            }
        }
    }
    let alignment = match (a.approx, within) {
        (Rule::Exact, None) => Alignment::Exact,
        (Rule::Exact, Some(_)) => {
            bail!("a duration --tolerance pairs nearest valid times: add --approx nearest")
        }
        (Rule::Nearest, Some(within)) => Alignment::Nearest { within },
        (Rule::Nearest, None) => bail!("--approx nearest needs a duration --tolerance (e.g. 5ms)"),
    };
    Ok(CompareOptions::new()
        .only(a.only.iter().cloned())
        .alignment(alignment)
        .value_tolerance(value)
        .create_time(!a.ignore_create_time)
        .overlap(a.overlap))
}

/// Compares and prints; a difference is [`Differ`].
pub fn run(json: bool, a: &Args) -> anyhow::Result<()> {
    let options = options(a)?;
    let ra = Recording::open(&a.a).with_context(|| format!("cannot read {}", a.a.display()))?;
    let rb = Recording::open(&a.b).with_context(|| format!("cannot read {}", a.b.display()))?;
    let report = compare(&ra, &rb, &options)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_table(&report);
    }
    if report.differs() { Err(Differ.into()) } else { Ok(()) }
}

/// A differing structure's inputs, compared, indented by depth.
fn print_inputs(name: &str, inputs: &[InputComparison], depth: usize) {
    for input in inputs {
        println!("{name}: {:width$}{}", "", input.words(), width = depth * 2);
        print_inputs(name, &input.inputs, depth + 1);
    }
}

fn print_table(r: &CompareReport) {
    println!("A: {}", r.a.display());
    println!("B: {}", r.b.display());
    for (which, damage) in [("A", &r.damage_a), ("B", &r.damage_b)] {
        if let Some(d) = damage {
            println!(
                "{which} is damaged at byte {}: {}; compared up to there",
                d.position, d.reason
            );
        }
    }
    println!(
        "{:<22} {:>8} {:>8} {:>8} {:>9} {:>7} {:>7}  result",
        "trajectory", "A", "B", "matched", "differing", "only A", "only B"
    );
    for t in &r.trajectories {
        let result = match t.presence {
            Presence::OnlyInA => "only in A",
            Presence::OnlyInB => "only in B",
            Presence::Both if t.differs() => "DIFFER",
            Presence::Both => "match",
        };
        println!(
            "{:<22} {:>8} {:>8} {:>8} {:>9} {:>7} {:>7}  {result}",
            t.name, t.count_a, t.count_b, t.matched, t.differing, t.only_in_a, t.only_in_b
        );
    }
    for t in r.trajectories.iter().filter(|t| t.presence == Presence::Both) {
        if let Some(d) = &t.type_difference {
            println!("{}: types differ: {d}", t.name);
        }
        if let Some(d) = &t.first_difference {
            let at = if d.valid_time == d.valid_time_b {
                format!("valid time {}", d.valid_time)
            } else {
                format!("valid time {} (B {})", d.valid_time, d.valid_time_b)
            };
            println!(
                "{}: first difference at {at}: {} = {} in A, {} in B",
                t.name, d.attribute, d.a, d.b
            );
            print_inputs(&t.name, &d.inputs, 1);
            for origin in &d.origins {
                println!("{}: {}", t.name, origin.words());
            }
        }
        if let Some(d) = &t.largest_deviation {
            println!(
                "{}: largest deviation {} in {} at valid time {} ({} in A, {} in B)",
                t.name, d.leaf.deviation, d.leaf.attribute, d.valid_time, d.leaf.a, d.leaf.b
            );
        }
        if let Some(v) = t.first_only_in_a {
            println!("{}: first structure only in A at valid time {v}", t.name);
        }
        if let Some(v) = t.first_only_in_b {
            println!("{}: first structure only in B at valid time {v}", t.name);
        }
    }
    println!("{}", if r.differs() { "the recordings differ" } else { "the recordings match" });
}
