//! `soak.png`: a run on one picture, three panels over the run's time — resident
//! memory per process, the domain's shared memory, and losses per trajectory — so a
//! leak shows as a slope and a loss as a step. The memory axes are zoomed to the data
//! (a 1 % slope must be visible), with a line at the baseline's time.

use std::collections::BTreeMap;
use std::path::Path;

use esgm_chart::plotters::coord::Shift;
use esgm_chart::plotters::prelude::*;
use esgm_chart::{ChartError, FAMILY, bounds, color, finish, number_label};

use super::sample::Sample;

/// Bytes in a MiB, the unit of the memory panels.
const MIB: f64 = 1024.0 * 1024.0;

/// Draws `samples` into `path`, marking the baseline at `baseline_t` seconds.
pub fn draw(samples: &[Sample], baseline_t: f64, title: &str, path: &Path) -> anyhow::Result<()> {
    let mut rss: BTreeMap<&str, Vec<(f64, f64)>> = BTreeMap::new();
    let mut losses: BTreeMap<&str, Vec<(f64, f64)>> = BTreeMap::new();
    for s in samples {
        for (name, p) in &s.processes {
            rss.entry(name).or_default().push((s.t, p.rss as f64 / MIB));
        }
        for (name, c) in &s.trajectories {
            let lost: u64 = c.losses.iter().map(|l| l.count).sum();
            losses.entry(name).or_default().push((s.t, lost as f64));
        }
    }
    let shm: BTreeMap<&str, Vec<(f64, f64)>> = BTreeMap::from([(
        "allocated (st_blocks)",
        samples.iter().map(|s| (s.t, s.shm.allocated as f64 / MIB)).collect(),
    )]);

    esgm_chart::register_font()?;
    let height = esgm_chart::SIZE.1 * 3 / 2;
    let root = BitMapBackend::new(path, (esgm_chart::SIZE.0, height)).into_drawing_area();
    root.fill(&WHITE).map_err(ChartError::draw)?;
    let root = root.titled(title, (FAMILY, 22)).map_err(ChartError::draw)?;
    let panels = root.split_evenly((3, 1));
    let x = bounds(samples.iter().map(|s| s.t));
    panel(&panels[0], "resident memory (VmRSS) per process", "MiB", x, &rss, baseline_t)?;
    panel(&panels[1], "the domain's shared memory in /dev/shm", "MiB", x, &shm, baseline_t)?;
    panel(&panels[2], "losses per trajectory (all causes)", "samples", x, &losses, baseline_t)?;
    Ok(())
}

/// One panel: a line per series, and the baseline as a dashed grey line.
fn panel(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    caption: &str,
    unit: &str,
    x: (f64, f64),
    series: &BTreeMap<&str, Vec<(f64, f64)>>,
    baseline_t: f64,
) -> Result<(), ChartError> {
    let y = bounds(series.values().flatten().map(|p| p.1));
    let mut chart = ChartBuilder::on(area)
        .caption(caption, (FAMILY, 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(75)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)
        .map_err(ChartError::draw)?;
    chart
        .configure_mesh()
        .x_desc("seconds")
        .y_desc(unit)
        .x_label_formatter(&|v| number_label(*v))
        .y_label_formatter(&|v| number_label(*v))
        .light_line_style(RGBColor(238, 238, 238))
        .label_style((FAMILY, 13))
        .axis_desc_style((FAMILY, 15))
        .draw()
        .map_err(ChartError::draw)?;
    let grey = RGBColor(127, 127, 127);
    chart
        .draw_series(DashedLineSeries::new(
            [(baseline_t, y.0), (baseline_t, y.1)],
            6,
            4,
            grey.stroke_width(1),
        ))
        .map_err(ChartError::draw)?
        .label("baseline")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], grey.stroke_width(1)));
    for (i, (name, points)) in series.iter().enumerate() {
        let c = color(i);
        chart
            .draw_series(LineSeries::new(points.iter().copied(), c.stroke_width(2)))
            .map_err(ChartError::draw)?
            .label(*name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    finish(&mut chart, area, SeriesLabelPosition::UpperLeft)
}
