//! The seed's queries (T1, T2) from the command line: `latest`, `nth`, `between`,
//! `at`, `closest`, `approx`.

use esgm_core::{EntityTrajectoryStructure, Sample, ValueApproximation};

use crate::session::{connect_tool as connect, trajectory};
use crate::show::print_sample;
use crate::time_arg::TimeArg;

/// A trajectory.
#[derive(Debug, clap::Args)]
pub struct One {
    /// Trajectory name.
    pub trajectory: String,
}

/// A trajectory and an index.
#[derive(Debug, clap::Args)]
pub struct Nth {
    /// Trajectory name.
    pub trajectory: String,
    /// 0 is the latest.
    pub n: usize,
}

/// A trajectory and an interval.
#[derive(Debug, clap::Args)]
pub struct Between {
    /// Trajectory name.
    pub trajectory: String,
    /// From (ns, RFC 3339, or relative to the latest: -5s).
    #[arg(allow_hyphen_values = true)]
    pub from: TimeArg,
    /// To (same forms).
    #[arg(allow_hyphen_values = true)]
    pub to: TimeArg,
}

/// A trajectory and a time.
#[derive(Debug, clap::Args)]
pub struct At {
    /// Trajectory name.
    pub trajectory: String,
    /// The time (ns, RFC 3339, or relative to the latest: -100ms).
    #[arg(allow_hyphen_values = true)]
    pub time: TimeArg,
}

/// How `approx` fills the gap between samples.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Method {
    /// The sample valid closest to the time.
    Closest,
    /// The latest sample valid before the time.
    MostRecent,
    /// Linear interpolation of numeric attributes (one that cannot be interpolated,
    /// such as sequences of different lengths, holds the most recent value, marked).
    Linear,
    /// Linear, but refused if an attribute cannot be interpolated.
    LinearStrict,
}

/// A trajectory, a time and an approximation.
#[derive(Debug, clap::Args)]
pub struct Approx {
    /// Trajectory name.
    pub trajectory: String,
    /// The time (ns, RFC 3339, or relative to the latest: -100ms).
    #[arg(allow_hyphen_values = true)]
    pub time: TimeArg,
    /// The approximation.
    #[arg(long, value_enum, default_value = "most-recent")]
    pub method: Method,
}

fn latest_vt(t: &impl EntityTrajectoryStructure) -> Option<i64> {
    // Empty has no latest; a relative time then says it needs one.
    t.get_latest().ok().map(|s| s.structure.valid_time())
}

fn print_all(json: bool, name: &str, samples: &[Sample]) {
    for s in samples {
        print_sample(json, name, s);
    }
}

/// `esgm latest`.
pub fn latest(domain: &str, json: bool, a: &One) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let t = trajectory(&esgm, &a.trajectory)?;
    print_sample(json, &a.trajectory, &t.get_latest()?);
    Ok(())
}

/// `esgm nth`.
pub fn nth(domain: &str, json: bool, a: &Nth) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let t = trajectory(&esgm, &a.trajectory)?;
    print_sample(json, &a.trajectory, &t.get_nth_latest(a.n)?);
    Ok(())
}

/// `esgm between`.
pub fn between(domain: &str, json: bool, a: &Between) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let t = trajectory(&esgm, &a.trajectory)?;
    let l = latest_vt(&t);
    let samples = t.get_between(a.from.resolve(l)?, a.to.resolve(l)?)?;
    print_all(json, &a.trajectory, &samples);
    Ok(())
}

/// `esgm at` (exact) and `esgm closest` (closest at or before).
pub fn at(domain: &str, json: bool, a: &At, closest: bool) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let t = trajectory(&esgm, &a.trajectory)?;
    let time = a.time.resolve(latest_vt(&t))?;
    let s = if closest { t.get_closest_at_or_before(time)? } else { t.get_at(time)? };
    print_sample(json, &a.trajectory, &s);
    Ok(())
}

/// `esgm approx`.
pub fn approx(domain: &str, json: bool, a: &Approx) -> anyhow::Result<()> {
    let esgm = connect(domain)?;
    let t = trajectory(&esgm, &a.trajectory)?;
    let time = a.time.resolve(latest_vt(&t))?;
    let method = match a.method {
        Method::Closest => ValueApproximation::Closest,
        Method::MostRecent => ValueApproximation::MostRecent,
        Method::Linear => ValueApproximation::Linear,
        Method::LinearStrict => ValueApproximation::LinearStrict,
    };
    print_sample(json, &a.trajectory, &t.get_at_approximating(time, &method)?);
    Ok(())
}
