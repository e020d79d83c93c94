//! `--plots DIR`: PNG charts of a run, drawn by the bench itself with `plotters`.
//!
//! - `latency_vs_payload_<wait>.png`: median one-way latency against payload size,
//!   one line per transport (esgm, raw iceoryx2, Unix socket, and Zenoh and ROS 1 when
//!   they ran), for busy-polling (`spin`) and blocking (`event`) receivers;
//! - `cdf_<wait>.png`: the latency distribution of every cross-process hop row;
//! - `domain_size.png`: connect, first add, idle CPU and memory against the number of
//!   trajectories in the domain (the `scale-*` rows), log-log;
//! - `fan_out.png`: the latency until the last of K readers holds a structure against
//!   K (the `fanout-*` rows, and the ROS 1 peer's `ros1-fanout-*` when it ran), with
//!   the bound of one wake-up per reader;
//! - `refsys_hot_path.png`: the Autoware reference system's hot path latency (front
//!   lidar to object collision estimator), one line per system that ran it, and
//!   `refsys_hot_path_nowork.png`, the same without the nodes' work.
//!
//! The setup (the bundled font, the palette, the legend) is esgm-chart's, shared with
//! `esgm plot`: no system font library is needed to build or to draw.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, anyhow};
use esgm_chart::plotters::prelude::*;
use esgm_chart::{SIZE, color, finish, number_label};

use crate::report::{Measurement, Report, Wait};

/// The transport a cross-process hop row measures, for the legend; `None` for rows
/// that are not such hops.
pub fn transport(m: &Measurement) -> Option<&'static str> {
    let name = m.name.as_str();
    let t = if name == "floor-iceoryx2" {
        "iceoryx2 raw"
    } else if name.starts_with("esgm-") && name.ends_with("-default") {
        "esgm, default wait"
    } else if name.starts_with("esgm-") {
        "esgm"
    } else if name.starts_with("uds-") {
        "Unix socket"
    } else if name.starts_with("zenoh-") {
        "Zenoh (shared memory)"
    } else if name.starts_with("ros1-") {
        "ROS 1 (roscpp)"
    } else {
        return None;
    };
    Some(t)
}

/// Draws every chart of `report` into `dir`; returns the files written.
pub fn draw(report: &Report, dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    esgm_chart::register_font()?;
    let mut written = Vec::new();
    for wait in Wait::BOTH {
        let rows: Vec<&Measurement> =
            report.scenarios.iter().filter(|m| m.wait == wait && transport(m).is_some()).collect();
        if rows.is_empty() {
            continue;
        }
        let path = dir.join(format!("latency_vs_payload_{}.png", wait.as_str()));
        latency_vs_payload(&rows, wait, &path)
            .with_context(|| format!("drawing {}", path.display()))?;
        written.push(path);
        let path = dir.join(format!("cdf_{}.png", wait.as_str()));
        let caption =
            format!("one-way latency CDF, process to process ({} receivers)", wait.as_str());
        cdf(&rows, &caption, &path).with_context(|| format!("drawing {}", path.display()))?;
        written.push(path);
    }
    for (file, nowork, caption) in [
        (
            "refsys_hot_path.png",
            false,
            "reference system: hot path latency CDF (front lidar -> collision estimator)",
        ),
        (
            "refsys_hot_path_nowork.png",
            true,
            "reference system, no work: hot path latency CDF (the middleware alone)",
        ),
    ] {
        let refsys: Vec<&Measurement> = report
            .scenarios
            .iter()
            .filter(|m| {
                crate::scenarios::refsys::is_hot_path_row(&m.name)
                    && m.name.ends_with("-nowork") == nowork
            })
            .collect();
        if !refsys.is_empty() {
            let path = dir.join(file);
            cdf(&refsys, caption, &path).with_context(|| format!("drawing {}", path.display()))?;
            written.push(path);
        }
    }
    let path = dir.join("domain_size.png");
    if domain_size(report, &path).with_context(|| format!("drawing {}", path.display()))? {
        written.push(path);
    }
    let path = dir.join("fan_out.png");
    if fan_out(report, &path).with_context(|| format!("drawing {}", path.display()))? {
        written.push(path);
    }
    Ok(written)
}

/// The number at the end of a row's name (`scale-connect-100` → 100).
fn size_of(name: &str, prefix: &str) -> Option<f64> {
    name.strip_prefix(prefix)?.parse::<u32>().ok().map(f64::from)
}

/// One series of a log-log chart: its label and its points.
type Series = (String, Vec<(f64, f64)>);

/// How a log-log chart's x axis reads: its range (`None`: around the points) and its
/// labels.
struct XAxis {
    range: Option<std::ops::Range<f64>>,
    label: fn(f64) -> String,
}

impl Default for XAxis {
    fn default() -> Self {
        Self { range: None, label: number_label }
    }
}

/// Draws `series` on a log-log chart; false (nothing drawn) if none has a point.
fn log_log(
    path: &Path,
    caption: &str,
    (x_desc, x_axis): (&str, XAxis),
    y_desc: &str,
    series: &[Series],
) -> anyhow::Result<bool> {
    let series: Vec<&Series> = series.iter().filter(|(_, p)| !p.is_empty()).collect();
    if series.is_empty() {
        return Ok(false);
    }
    let x = x_axis
        .range
        .unwrap_or_else(|| log_range(series.iter().flat_map(|(_, p)| p.iter().map(|&(x, _)| x))));
    let y = log_range(series.iter().flat_map(|(_, p)| p.iter().map(|&(_, y)| y)));
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, ("sans-serif", 24))
        .margin(20)
        .x_label_area_size(55)
        .y_label_area_size(75)
        .build_cartesian_2d(x.log_scale(), y.log_scale())
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(&|v| (x_axis.label)(*v))
        .y_label_formatter(&|v| number_label(*v))
        .light_line_style(RGBColor(238, 238, 238))
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 17))
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    for (i, (label, points)) in series.iter().enumerate() {
        let c = color(i);
        let mut points = points.clone();
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(points.clone(), c.stroke_width(2)))
            .map_err(|e| anyhow!("{e}"))?
            .label(label.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart
            .draw_series(points.into_iter().map(|p| Circle::new(p, 5, c.filled())))
            .map_err(|e| anyhow!("{e}"))?;
    }
    finish(&mut chart, &root, SeriesLabelPosition::UpperLeft)?;
    Ok(true)
}

/// Connect, first add, idle CPU and memory against the domain's trajectories.
fn domain_size(report: &Report, path: &Path) -> anyhow::Result<bool> {
    let rows = |prefix: &str| -> Vec<(f64, f64)> {
        report
            .scenarios
            .iter()
            .filter_map(|m| Some((size_of(&m.name, prefix)?, m.p50_ns as f64 / 1e6)))
            .collect()
    };
    let memory = |prefix: &str| -> Vec<(f64, f64)> {
        report
            .memory
            .iter()
            .filter_map(|m| Some((size_of(&m.name, prefix)?, m.bytes.max(1) as f64 / 1048576.0)))
            .collect()
    };
    let series = [
        ("connect p50 (ms)".to_owned(), rows("scale-connect-")),
        ("first add from a non-writer p50 (ms)".to_owned(), rows("scale-first-add-")),
        ("idle CPU (ms per second)".to_owned(), rows("scale-idle-")),
        ("private memory (MiB)".to_owned(), memory("scale-private-")),
        ("shared memory touched (MiB)".to_owned(), memory("scale-shm-")),
    ];
    log_log(
        path,
        "cost against the domain's size",
        ("trajectories in the domain (log scale)", XAxis::default()),
        "value, in the unit of each line (log scale)",
        &series,
    )
}

/// Latency until the last of K readers holds a structure, against K.
fn fan_out(report: &Report, path: &Path) -> anyhow::Result<bool> {
    let rows = |prefix: &str, p99: bool, wait: Wait| -> Vec<(f64, f64)> {
        report
            .scenarios
            .iter()
            .filter(|m| m.wait == wait)
            .filter_map(|m| {
                let ns = if p99 { m.p99_ns } else { m.p50_ns };
                Some((size_of(&m.name, prefix)?, us(ns)))
            })
            .collect()
    };
    let esgm = rows("fanout-", false, Wait::Event);
    // One wake-up per reader: K times the single reader's median.
    let one = esgm.iter().find(|&&(k, _)| k == 1.0).map(|&(_, us)| us);
    let bound: Vec<(f64, f64)> =
        one.map(|one| esgm.iter().map(|&(k, _)| (k, k * one)).collect()).unwrap_or_default();
    let series = [
        ("esgm p50".to_owned(), esgm),
        ("esgm p99".to_owned(), rows("fanout-", true, Wait::Event)),
        ("one wake-up per reader (K × fanout-1 p50)".to_owned(), bound),
        ("ROS 1 (roscpp) p50".to_owned(), rows("ros1-fanout-", false, Wait::Event)),
        ("esgm busy-wait readers p50".to_owned(), rows("fanout-", false, Wait::Spin)),
    ];
    log_log(
        path,
        "until the last of K reader processes holds it",
        ("reader processes K (log scale)", XAxis::default()),
        "latency (µs, log scale)",
        &series,
    )
}

/// `64 B`, `1 kB`, `922 kB`.
fn bytes_label(v: f64) -> String {
    if v >= 1e6 {
        format!("{:.1} MB", v / 1e6)
    } else if v >= 1e3 {
        format!("{:.0} kB", v / 1e3)
    } else {
        format!("{v:.0} B")
    }
}

fn us(ns: u64) -> f64 {
    (ns.max(1)) as f64 / 1000.0
}

/// Bounds of a log axis around `values`, with some room.
fn log_range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values.fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if lo > hi {
        return 0.1..10.0;
    }
    (lo / 2.0).max(1e-3)..hi * 2.0
}

fn latency_vs_payload(rows: &[&Measurement], wait: Wait, path: &Path) -> anyhow::Result<()> {
    let mut transports: Vec<&str> = Vec::new();
    for m in rows {
        if let Some(t) = transport(m) {
            if !transports.contains(&t) {
                transports.push(t);
            }
        }
    }
    let series: Vec<Series> = transports
        .iter()
        .map(|t| {
            let points = rows
                .iter()
                .filter(|m| transport(m) == Some(t))
                .map(|m| (m.payload_bytes.max(1) as f64, us(m.p50_ns)))
                .collect();
            ((*t).to_owned(), points)
        })
        .collect();
    // Always from the 64-byte floor to past the image, so runs compare.
    let x_axis = XAxis { range: Some(16.0..4e6), label: bytes_label };
    log_log(
        path,
        &format!("median one-way latency vs payload size ({} receivers)", wait.as_str()),
        ("payload (bytes, log scale)", x_axis),
        "p50 latency (µs, log scale)",
        &series,
    )?;
    Ok(())
}

fn cdf(rows: &[&Measurement], caption: &str, path: &Path) -> anyhow::Result<()> {
    let x = log_range(rows.iter().flat_map(|m| m.cdf.iter().map(|&(_, ns)| us(ns))));
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, ("sans-serif", 24))
        .margin(20)
        .x_label_area_size(55)
        .y_label_area_size(75)
        .build_cartesian_2d(x.log_scale(), 0f64..1f64)
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .configure_mesh()
        .x_desc("latency (µs, log scale)")
        .y_desc("fraction of hops at or below")
        .x_label_formatter(&|v| number_label(*v))
        .light_line_style(RGBColor(238, 238, 238))
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 17))
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    for (i, m) in rows.iter().filter(|m| !m.cdf.is_empty()).enumerate() {
        let c = color(i);
        let points: Vec<(f64, f64)> = m.cdf.iter().map(|&(q, ns)| (us(ns), q)).collect();
        let label = format!("{} ({} B)", m.name, m.payload_bytes);
        chart
            .draw_series(LineSeries::new(points, c.stroke_width(2)))
            .map_err(|e| anyhow!("{e}"))?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    Ok(finish(&mut chart, &root, SeriesLabelPosition::LowerRight)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::latency::Latency;

    #[test]
    fn charts_are_drawn_without_system_fonts() {
        let mut rows = Vec::new();
        for (name, bytes, ns) in
            [("floor-iceoryx2", 64, 900), ("esgm-small", 120, 1300), ("esgm-image", 921_760, 1500)]
        {
            let mut l = Latency::new().unwrap();
            for k in 0..100 {
                l.record_ns(ns + k * 10);
            }
            rows.push(l.measurement(name, Wait::Spin).payload_bytes(bytes));
        }
        let report = Report { scenarios: rows, ..Report::default() };
        let dir = tempfile::tempdir().unwrap();
        let files = draw(&report, dir.path()).unwrap();
        assert_eq!(files.len(), 2);
        for f in files {
            let bytes = std::fs::read(&f).unwrap();
            assert!(bytes.starts_with(b"\x89PNG"), "{} is not a PNG", f.display());
        }
    }

    #[test]
    fn domain_size_and_fan_out_are_drawn_from_their_rows() {
        let mut rows = Vec::new();
        for (name, ns) in [
            ("scale-connect-10", 9_000_000),
            ("scale-connect-1000", 10_000_000),
            ("scale-idle-10", 100_000),
            ("scale-idle-1000", 900_000),
            ("fanout-1", 90_000),
            ("fanout-8", 400_000),
        ] {
            let mut l = Latency::new().unwrap();
            l.record_ns(ns);
            rows.push(l.measurement(name, Wait::Event));
        }
        let memory = vec![crate::report::MemoryRow {
            name: "scale-private-10".into(),
            after_structures: 0,
            bytes: 5 << 20,
            mapped_bytes: None,
            note: String::new(),
        }];
        let report = Report { scenarios: rows, memory, ..Report::default() };
        let dir = tempfile::tempdir().unwrap();
        let files = draw(&report, dir.path()).unwrap();
        let names: Vec<_> =
            files.iter().map(|f| f.file_name().unwrap().to_string_lossy().into_owned()).collect();
        assert_eq!(names, ["domain_size.png", "fan_out.png"]);
        // Without such rows, no such charts.
        let empty = tempfile::tempdir().unwrap();
        assert!(draw(&Report::default(), empty.path()).unwrap().is_empty());
        assert_eq!(size_of("fanout-64", "fanout-"), Some(64.0));
        assert_eq!(size_of("fanout-x", "fanout-"), None);
    }
}
