//! `scale.png`: one run on one picture — each process's private memory against what
//! it writes and reads, and each class's latency percentiles — so a process that costs
//! more than its use, or a class that lags, stands out.

use std::path::Path;

use esgm_chart::plotters::prelude::*;
use esgm_chart::{ChartError, FAMILY, bounds, color, number_label};

use super::Measured;

const MIB: f64 = 1024.0 * 1024.0;

/// Draws `m` into `path`.
pub fn draw(m: &Measured, path: &Path) -> anyhow::Result<()> {
    esgm_chart::register_font()?;
    let root = BitMapBackend::new(path, esgm_chart::SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(ChartError::draw)?;
    let title = format!(
        "esgm scale: {} trajectories, {} processes, tf read by {}",
        m.trajectories, m.processes, m.tf_readers
    );
    let root = root.titled(&title, (FAMILY, 22)).map_err(ChartError::draw)?;
    let panels = root.split_evenly((1, 2));

    // Private memory per process against the trajectories it uses.
    let points: Vec<(f64, f64)> =
        m.workers.iter().map(|w| ((w.writes + w.reads) as f64, w.private as f64 / MIB)).collect();
    let x = bounds(points.iter().map(|p| p.0).chain([0.0]));
    let y = bounds(points.iter().map(|p| p.1).chain([0.0]));
    let mut chart = ChartBuilder::on(&panels[0])
        .caption("private memory per process (RssAnon, idle)", (FAMILY, 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)
        .map_err(ChartError::draw)?;
    chart
        .configure_mesh()
        .x_desc("trajectories it writes or reads")
        .y_desc("MiB")
        .x_label_formatter(&|v| number_label(*v))
        .y_label_formatter(&|v| number_label(*v))
        .label_style((FAMILY, 13))
        .axis_desc_style((FAMILY, 15))
        .draw()
        .map_err(ChartError::draw)?;
    chart
        .draw_series(points.iter().map(|p| Circle::new(*p, 4, color(0).filled())))
        .map_err(ChartError::draw)?;

    // Latency percentiles per class.
    let classes: Vec<_> = m.latency.iter().collect();
    let ymax = classes.iter().map(|(_, l)| f64::from(l.p99_us)).fold(1.0, f64::max) * 1.1;
    let mut chart = ChartBuilder::on(&panels[1])
        .caption("latency until a reader holds it (blue p50, orange p99)", (FAMILY, 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(-0.5..(classes.len() as f64 - 0.5).max(0.5), 0.0..ymax)
        .map_err(ChartError::draw)?;
    let labels: Vec<&str> = classes.iter().map(|(c, _)| c.label()).collect();
    chart
        .configure_mesh()
        .x_labels(classes.len().max(1))
        .x_label_formatter(&|v| {
            let i = v.round();
            if (v - i).abs() < 0.01 && i >= 0.0 {
                labels.get(i as usize).map_or_else(String::new, |s| (*s).to_owned())
            } else {
                String::new()
            }
        })
        .y_desc("µs")
        .y_label_formatter(&|v| number_label(*v))
        .label_style((FAMILY, 13))
        .axis_desc_style((FAMILY, 15))
        .draw()
        .map_err(ChartError::draw)?;
    for (i, (_, l)) in classes.iter().enumerate() {
        let x = i as f64;
        for (k, (dx, v)) in [(-0.2, l.p50_us), (0.2, l.p99_us)].into_iter().enumerate() {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(x + dx - 0.15, 0.0), (x + dx + 0.15, f64::from(v))],
                    color(k).filled(),
                )))
                .map_err(ChartError::draw)?;
        }
    }
    root.present().map_err(ChartError::draw)?;
    Ok(())
}
