//! `esgm plot TRAJ ATTR… -o file.png`: attributes of a trajectory over valid time, one
//! chart per call, from a running system (`get_between`) or from a recording
//! (`--file rec.mcap`). The x axis is seconds of valid time from the first sample
//! plotted; the type's units label the series where its sorts give them.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use esgm_chart::plotters::prelude::*;
use esgm_chart::{ChartError, FAMILY, SIZE, bounds, color, finish, number_label};
use esgm_core::{EntityStructure, EntityTrajectoryStructure, Time};
use esgm_recording::Recording;

use crate::series::{self, Field};
use crate::session::{connect, trajectory};
use crate::time_arg::{TimeArg, display};

/// `esgm plot` options.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Trajectory name.
    pub trajectory: String,
    /// Attributes to plot (numbers, or a geometric value's field: `linear.x`).
    #[arg(required = true)]
    pub attributes: Vec<String>,
    /// From this valid time (ns, RFC 3339, or relative to the latest: -5s); default:
    /// the earliest sample.
    #[arg(long, allow_hyphen_values = true)]
    pub from: Option<TimeArg>,
    /// To this valid time (same forms); default: the latest sample.
    #[arg(long, allow_hyphen_values = true)]
    pub to: Option<TimeArg>,
    /// Read the trajectory from this recording instead of the running system.
    #[arg(long)]
    pub file: Option<PathBuf>,
    /// The PNG file to write.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// What a chart is drawn from: the trajectory's type name and its structures by valid
/// time.
struct Source {
    type_name: String,
    structures: Vec<EntityStructure>,
}

/// Writes the chart and prints where.
pub fn run(domain: &str, json: bool, a: &Args) -> anyhow::Result<()> {
    let (fields, source) = match &a.file {
        Some(file) => from_recording(file, a)?,
        None => from_system(domain, a)?,
    };
    let points = draw(&a.trajectory, &source, &fields, &a.output)
        .with_context(|| format!("cannot write {}", a.output.display()))?;
    if json {
        let v = serde_json::json!({"file": a.output, "trajectory": a.trajectory,
                                   "structures": source.structures.len(), "points": points});
        println!("{v}");
    } else {
        println!(
            "{}: {} of `{}` over {} structures ({points} points)",
            a.output.display(),
            a.attributes.join(", "),
            a.trajectory,
            source.structures.len()
        );
    }
    Ok(())
}

fn range(a: &Args, earliest: Time, latest: Time) -> anyhow::Result<(Time, Time)> {
    let from = a.from.as_ref().map_or(Ok(earliest), |t| t.resolve(Some(latest)))?;
    let to = a.to.as_ref().map_or(Ok(latest), |t| t.resolve(Some(latest)))?;
    if from > to {
        bail!("--from {} is after --to {}", display(from), display(to));
    }
    Ok((from, to))
}

fn from_system(domain: &str, a: &Args) -> anyhow::Result<(Vec<Field>, Source)> {
    let esgm = connect(domain)?;
    let t = trajectory(&esgm, &a.trajectory)?;
    let ty = t.entity_type()?;
    let fields = resolve_all(&ty, a)?;
    let (Ok(earliest), Ok(latest)) = (t.start_time(), t.end_time()) else {
        bail!("`{}` holds no samples to plot", a.trajectory);
    };
    let (from, to) = range(a, earliest, latest)?;
    let structures =
        t.get_between(from, to)?.into_iter().map(|s| s.structure.to_structure()).collect();
    Ok((fields, Source { type_name: ty.name, structures }))
}

fn from_recording(file: &Path, a: &Args) -> anyhow::Result<(Vec<Field>, Source)> {
    let rec = Recording::open(file).with_context(|| format!("cannot read {}", file.display()))?;
    let Some(index) = rec.trajectories.iter().position(|t| t.info.name == a.trajectory) else {
        let names: Vec<&str> = rec.trajectories.iter().map(|t| t.info.name.as_str()).collect();
        bail!(
            "{} has no trajectory `{}`; it has {}",
            file.display(),
            a.trajectory,
            if names.is_empty() { "none".to_owned() } else { names.join(", ") }
        );
    };
    let recorded = &rec.trajectories[index];
    let ty = &recorded.types.root;
    let fields = resolve_all(ty, a)?;
    let Some((earliest, latest)) = recorded.valid_range else {
        bail!("`{}` has no samples in {}", a.trajectory, file.display());
    };
    let (from, to) = range(a, earliest, latest)?;
    let mut structures = Vec::new();
    for sample in rec.samples()? {
        let sample = sample.with_context(|| format!("reading {}", file.display()))?;
        let v = sample.structure.valid_time;
        if sample.trajectory == index && (from..=to).contains(&v) {
            structures.push(sample.structure);
        }
    }
    // File order is add order; the chart's is valid time.
    structures.sort_by_key(|es| es.valid_time);
    Ok((fields, Source { type_name: ty.name.clone(), structures }))
}

fn resolve_all(ty: &esgm_core::EntityStructureType, a: &Args) -> anyhow::Result<Vec<Field>> {
    a.attributes.iter().map(|p| series::resolve(ty, &a.trajectory, p)).collect()
}

/// Draws the chart into `path`; returns the number of points drawn.
fn draw(trajectory: &str, source: &Source, fields: &[Field], path: &Path) -> anyhow::Result<usize> {
    let t0 = source.structures.first().map_or(0, |es| es.valid_time);
    let seconds = |t: Time| (t - t0) as f64 / 1e9;
    let series: Vec<Vec<(f64, f64)>> = fields
        .iter()
        .map(|f| {
            source
                .structures
                .iter()
                .filter_map(|es| Some((seconds(es.valid_time), f.value(es)?)))
                .collect()
        })
        .collect();
    let points: usize = series.iter().map(Vec::len).sum();
    let all = || series.iter().flatten();
    let (x_lo, x_hi) = bounds(all().map(|p| p.0));
    let (y_lo, y_hi) = bounds(all().map(|p| p.1));

    esgm_chart::register_font()?;
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(ChartError::draw)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("{trajectory} ({})", source.type_name), (FAMILY, 24))
        .margin(20)
        .x_label_area_size(55)
        .y_label_area_size(75)
        .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)
        .map_err(ChartError::draw)?;
    let units: Vec<&str> = fields.iter().filter_map(|f| f.unit).collect();
    let y_desc = match units.first() {
        Some(u) if units.len() == fields.len() && units.iter().all(|v| v == u) => {
            format!("value ({u})")
        }
        _ => "value".to_owned(),
    };
    chart
        .configure_mesh()
        .x_desc(format!("valid time (s) from {}", crate::time_arg::display(t0)))
        .y_desc(y_desc)
        .x_label_formatter(&|v| number_label(*v))
        .y_label_formatter(&|v| number_label(*v))
        .light_line_style(RGBColor(238, 238, 238))
        .label_style((FAMILY, 15))
        .axis_desc_style((FAMILY, 17))
        .draw()
        .map_err(ChartError::draw)?;
    for (i, (field, points)) in fields.iter().zip(series).enumerate() {
        let c = color(i);
        let dots = points.len() <= 200;
        chart
            .draw_series(LineSeries::new(points.iter().copied(), c.stroke_width(2)))
            .map_err(ChartError::draw)?
            .label(field.label())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        if dots {
            chart
                .draw_series(points.into_iter().map(|p| Circle::new(p, 3, c.filled())))
                .map_err(ChartError::draw)?;
        }
    }
    finish(&mut chart, &root, SeriesLabelPosition::UpperRight)?;
    Ok(points)
}
