//! The printed table: one row per measurement, its baseline's ratio beside it, the
//! meaning of each method and every note below.

use std::fmt::Write as _;

use crate::config::RunConfig;
use crate::report::{Measurement, Method, Report, Wait};
use crate::scenario::EVENT_GAP;
use crate::target::ratio_label;

const HEADER: [&str; 13] = [
    "name",
    "payload B",
    "wait",
    "method",
    "n",
    "p50",
    "p99",
    "p99.9",
    "max",
    "baseline (same wait)",
    "p50 vs baseline",
    "p99 vs baseline",
    "p50 vs floor",
];
/// Columns whose cells are right-aligned (numbers).
const RIGHT: [bool; 13] =
    [false, true, false, false, true, true, true, true, true, false, true, true, true];

/// The scenario every latency row is also compared with: raw iceoryx2, same wait.
pub const FLOOR: &str = "floor-iceoryx2";

/// The report as a table, with a legend and the notes.
pub fn render(report: &Report, config: &RunConfig) -> String {
    let mut rows: Vec<[String; 13]> = vec![HEADER.map(str::to_owned)];
    for m in &report.scenarios {
        let base = report.baseline_of(m);
        let (baseline, p50_vs, p99_vs) = match (&m.baseline, base) {
            (Some(_), Some(b)) => {
                (b.name.clone(), compare(m.p50_ns, b.p50_ns), compare(m.p99_ns, b.p99_ns))
            }
            (Some(name), None) if report.has_failed(name, m.wait) => {
                (format!("{name} (failed)"), "-".into(), "-".into())
            }
            (Some(name), None) => (format!("{name} (not run)"), "-".into(), "-".into()),
            (None, _) => ("-".into(), "-".into(), "-".into()),
        };
        rows.push([
            m.name.clone(),
            thousands(m.payload_bytes),
            m.wait.as_str().to_owned(),
            m.method.label().to_owned(),
            thousands(m.n),
            duration(m.p50_ns),
            duration(m.p99_ns),
            duration(m.p999_ns),
            duration(m.max_ns),
            baseline,
            p50_vs,
            p99_vs,
            vs_floor(report, m),
        ]);
    }

    let mut widths = [0usize; 13];
    for row in &rows {
        for (w, cell) in widths.iter_mut().zip(row) {
            *w = (*w).max(cell.chars().count());
        }
    }

    let mut out = String::new();
    let pinning = match config.pin {
        Some(p) => format!(
            "pinned: measuring thread on core {}, peers on core {}",
            p.measuring_core(),
            p.peer_core()
        ),
        None => "not pinned".to_owned(),
    };
    let _ = writeln!(out, "esgm-bench: latency, baselines measured in the same run ({pinning})");
    let _ = writeln!(out, "{}", report.machine.describe());
    for row in &rows {
        let mut line = String::new();
        for (i, cell) in row.iter().enumerate() {
            let pad = widths[i] - cell.chars().count();
            if i > 0 {
                line.push_str("  ");
            }
            if RIGHT[i] {
                line.extend(std::iter::repeat_n(' ', pad));
                line.push_str(cell);
            } else {
                line.push_str(cell);
                line.extend(std::iter::repeat_n(' ', pad));
            }
        }
        let _ = writeln!(out, "{}", line.trim_end());
    }

    let mut methods: Vec<Method> = Vec::new();
    for m in &report.scenarios {
        if !methods.contains(&m.method) {
            methods.push(m.method);
        }
    }
    for method in methods {
        let _ = writeln!(out, "{:>8}: {}", method.label(), method.legend());
    }
    for wait in Wait::BOTH {
        if report.scenarios.iter().any(|m| m.wait == wait) {
            let _ = writeln!(out, "{:>8}: {}", wait.as_str(), wait_legend(wait));
        }
    }
    let _ = writeln!(out, "{:>8}: ratio to the baseline row (and the difference)", "vs");
    let _ = writeln!(
        out,
        "{:>8}: p50 / p50 of {FLOOR} with the same wait (raw iceoryx2, 64 bytes), this run",
        "floor"
    );

    out.push_str(&targets(report));
    out.push_str(&memory(report));
    for s in &report.skipped {
        let _ = writeln!(out, "{}: skipped — {}", s.name, s.reason);
    }
    for f in &report.failed {
        let _ = writeln!(out, "{} ({}): FAILED — {}", f.name, f.wait.as_str(), f.reason);
    }

    let notes: Vec<String> = report.scenarios.iter().flat_map(notes_of).collect();
    if !notes.is_empty() {
        let _ = writeln!(out, "notes:");
        for n in notes {
            let _ = writeln!(out, "  {n}");
        }
    }
    out
}

/// The targets of the run, one aligned line each.
fn targets(report: &Report) -> String {
    let mut out = String::new();
    if report.targets.is_empty() {
        return out;
    }
    let _ = writeln!(
        out,
        "targets (p50 of a row / p50 of another, same wait, this run; shown, not asserted):"
    );
    let lines: Vec<[String; 5]> = report
        .targets
        .iter()
        .map(|t| {
            let what = format!("{} ({})", t.label(), t.wait.as_str());
            match t.evaluate(report) {
                Ok(o) => [
                    what,
                    format!("×{}", ratio_label(o.p50_ratio)),
                    format!("(p99 ×{})", ratio_label(o.p99_ratio)),
                    format!("target {}", t.bound_label()),
                    if o.met { "met".to_owned() } else { "MISSED".to_owned() },
                ],
                Err(missing) => [
                    what,
                    "-".to_owned(),
                    String::new(),
                    format!("target {}", t.bound_label()),
                    missing
                        .iter()
                        .map(|row| {
                            let how =
                                if report.has_failed(row, t.wait) { "failed" } else { "not run" };
                            format!("({row} {how})")
                        })
                        .collect::<Vec<_>>()
                        .join(" "),
                ],
            }
        })
        .collect();
    let mut widths = [0usize; 5];
    for line in &lines {
        for (w, cell) in widths.iter_mut().zip(line) {
            *w = (*w).max(cell.chars().count());
        }
    }
    for line in &lines {
        let mut text = String::new();
        for (i, cell) in line.iter().enumerate() {
            let pad = widths[i] - cell.chars().count();
            text.push_str("  ");
            // The ratio is a number: right-aligned.
            if i == 1 {
                text.extend(std::iter::repeat_n(' ', pad));
                text.push_str(cell);
            } else {
                text.push_str(cell);
                text.extend(std::iter::repeat_n(' ', pad));
            }
        }
        let _ = writeln!(out, "{}", text.trim_end());
    }
    out
}

/// `×1.32`: a latency row's p50 over the floor's (same wait); `-` for rows that are
/// not hops (queries, compute calls, lateness) or without a floor in the run.
fn vs_floor(report: &Report, m: &Measurement) -> String {
    if matches!(m.method, Method::Call | Method::Lateness | Method::PerItem | Method::CpuPerSecond)
    {
        return "-".to_owned();
    }
    match report.scenarios.iter().find(|f| f.name == FLOOR && f.wait == m.wait) {
        Some(f) if f.p50_ns > 0 => format!("×{}", ratio_label(m.p50_ns as f64 / f.p50_ns as f64)),
        _ => "-".to_owned(),
    }
}

/// The memory section: one line per figure.
fn memory(report: &Report) -> String {
    let mut out = String::new();
    if report.memory.is_empty() {
        return out;
    }
    let _ =
        writeln!(out, "memory (resident: VmRSS; shared memory: /dev/shm files of the trajectory):");
    let width = report.memory.iter().map(|m| m.name.chars().count()).max().unwrap_or(0);
    for m in &report.memory {
        let amount = if m.name.ends_with("-rate") {
            format!("{}/s", thousands(m.bytes))
        } else {
            match m.mapped_bytes {
                Some(mapped) => format!("{} committed of {} mapped", bytes(m.bytes), bytes(mapped)),
                None => bytes(m.bytes),
            }
        };
        let _ = writeln!(
            out,
            "  {:<width$}  after {:>9}  {amount}  ({})",
            m.name,
            thousands(m.after_structures),
            m.note
        );
    }
    out
}

/// `12.3 MiB`.
fn bytes(b: u64) -> String {
    format!("{:.1} MiB", b as f64 / (1024.0 * 1024.0))
}

fn wait_legend(wait: Wait) -> String {
    match wait {
        Wait::Spin => {
            "receivers busy-poll (try_recv, an iceoryx2 receive, a non-blocking read)".to_owned()
        }
        Wait::Event => format!(
            "receivers block until woken (recv, an iceoryx2 event, a blocking read; `-default` \
             rows spin briefly first); each hop starts {} µs after the last, so they are asleep \
             when it comes (one wake-up per hop)",
            EVENT_GAP.as_micros()
        ),
    }
}

fn notes_of(m: &Measurement) -> Vec<String> {
    let who = format!("{} ({})", m.name, m.wait.as_str());
    let write = m.producer_write_p50_ns.map(|ns| {
        format!(
            "{who}: producer's write of each structure, before and outside its hop: p50 {}",
            duration(ns)
        )
    });
    write.into_iter().chain(m.notes.iter().map(|n| format!("{who}: {n}"))).collect()
}

/// `×1.84 (+120 ns)`: the ratio and the difference.
fn compare(value: u64, base: u64) -> String {
    let diff = value as i128 - base as i128;
    let sign = if diff < 0 { "-" } else { "+" };
    let diff = duration(u64::try_from(diff.unsigned_abs()).unwrap_or(u64::MAX));
    if base == 0 {
        format!("- ({sign}{diff})")
    } else {
        format!("×{:.2} ({sign}{diff})", value as f64 / base as f64)
    }
}

/// Nanoseconds with a unit and three significant digits: `812 ns`, `12.3 µs`, `1.05 ms`.
pub fn duration(ns: u64) -> String {
    const UNITS: [(f64, &str); 3] = [(1e9, "s"), (1e6, "ms"), (1e3, "µs")];
    let v = ns as f64;
    for (scale, unit) in UNITS {
        if v >= scale {
            let x = v / scale;
            return if x >= 100.0 {
                format!("{x:.0} {unit}")
            } else if x >= 10.0 {
                format!("{x:.1} {unit}")
            } else {
                format!("{x:.2} {unit}")
            };
        }
    }
    format!("{ns} ns")
}

/// `921,600`.
fn thousands(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::with_capacity(digits.len() + digits.len() / 3);
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i) % 3 == 0 {
            out.push(',');
        }
        out.push(c);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::latency::Latency;
    use crate::target::Target;

    #[test]
    fn durations_and_counts_read_well() {
        assert_eq!(duration(812), "812 ns");
        assert_eq!(duration(1_234), "1.23 µs");
        assert_eq!(duration(12_345), "12.3 µs");
        assert_eq!(duration(123_456), "123 µs");
        assert_eq!(duration(1_050_000), "1.05 ms");
        assert_eq!(thousands(921_600), "921,600");
        assert_eq!(thousands(100), "100");
        assert_eq!(compare(300, 100), "×3.00 (+200 ns)");
        assert_eq!(compare(50, 100), "×0.50 (-50 ns)");
    }

    #[test]
    fn rows_show_their_baseline_ratio_and_notes() {
        let mut l = Latency::new().unwrap();
        l.record_ns(100);
        let floor = l.measurement("floor", Wait::Spin);
        let mut l = Latency::new().unwrap();
        l.record_ns(250);
        let hop = l.measurement("hop", Wait::Spin).baseline("floor").note("shared");
        let orphan = l.measurement("hop", Wait::Event).baseline("floor");
        let report = Report {
            scenarios: vec![floor, hop, orphan],
            targets: vec![
                Target::at_most("hop", "floor", Wait::Spin, 3.0),
                Target::at_most("hop", "floor", Wait::Event, 3.0),
            ],
            memory: Vec::new(),
            skipped: Vec::new(),
            failed: Vec::new(),
            machine: crate::report::Machine {
                cpuidle_driver: Some("haltpoll".into()),
                guest_halt_poll_ns: Some(0),
                cpu_latency_us: Some(0),
            },
        };
        let text = render(&report, &RunConfig::default());
        assert!(
            text.contains(
                "idle cores: cpuidle haltpoll, guest halt polling 0 ns, wake-up held within 0 µs"
            ),
            "{text}"
        );
        let target = "hop / floor (spin)   ×2.50  (p99 ×2.50)  target ≤ ×3.00  met";
        assert!(text.contains(target), "{text}");
        assert!(text.contains("(floor not run)"), "{text}");
        assert!(text.contains("×2.50 (+150 ns)"), "{text}");
        assert!(text.contains("floor (not run)"), "{text}");
        assert!(text.contains("hop (spin): shared"), "{text}");
        assert!(text.contains("rtt/2:"), "{text}");
    }

    #[test]
    fn an_empty_row_prints_as_a_failure_not_as_zeros() {
        let mut l = Latency::new().unwrap();
        l.record_ns(100);
        let floor = l.measurement("floor", Wait::Event);
        let empty = Latency::new().unwrap().measurement("e2e", Wait::Event).if_empty("no blob");
        let hop = l.measurement("hop", Wait::Event).baseline("e2e");
        let mut report = Report {
            targets: vec![Target::at_most("e2e", "floor", Wait::Event, 2.0)],
            ..Report::default()
        };
        report.add_rows(vec![floor, empty, hop]);
        let text = render(&report, &RunConfig::default());
        assert!(text.contains("e2e (event): FAILED — no samples: no blob"), "{text}");
        // No table row of zeros for it.
        assert!(!text.lines().any(|l| l.starts_with("e2e ") && !l.contains("FAILED")), "{text}");
        assert!(text.contains("(e2e failed)"), "{text}");
        assert!(text.contains("e2e (failed)"), "{text}");
    }
}
