//! The soak's judgement of a run: memory growth after the warm-up against the target,
//! losses by cause, and what keeps the comparison honest (every process measured at
//! both ends, none restarted, data still flowing).
//!
//! Growth is measured from the *baseline* (the first sample at or after the warm-up:
//! caches, queues and allocator pools fill during the first minute, and that is not a
//! leak) to the last sample. A process that restarted has fresh memory, so it could
//! hide a leak: a restart fails the run. So does a trajectory that added nothing after
//! the baseline: flat memory of a stalled system proves nothing.

use super::sample::{Loss, Sample};

/// The growth of one figure from the baseline to the end.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Growth {
    /// What grew: a process name, or `shared memory`.
    pub what: String,
    /// Bytes at the baseline.
    pub baseline: u64,
    /// Bytes at the end.
    pub end: u64,
    /// Most bytes at any sample from the baseline on.
    pub peak: u64,
    /// `(end − baseline) / baseline`, in percent (infinite from a zero baseline).
    pub percent: f64,
    /// Below the target.
    pub within: bool,
}

impl Growth {
    fn of(what: &str, points: &[(f64, u64)], target_percent: f64) -> Option<Self> {
        let (&(_, baseline), &(_, end)) = (points.first()?, points.last()?);
        let peak = points.iter().map(|p| p.1).max().unwrap_or(end);
        let percent = growth_percent(baseline, end);
        Some(Growth {
            what: what.to_owned(),
            baseline,
            end,
            peak,
            percent,
            within: percent < target_percent,
        })
    }
}

/// `(end − baseline) / baseline` in percent; from 0 bytes, any growth is infinite.
pub fn growth_percent(baseline: u64, end: u64) -> f64 {
    if baseline == 0 {
        return if end == 0 { 0.0 } else { f64::INFINITY };
    }
    (end as f64 - baseline as f64) / baseline as f64 * 100.0
}

/// One trajectory's losses under one cause at the end of the run.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TrajectoryLoss {
    /// The trajectory.
    pub trajectory: String,
    /// The cause, how many, and whether it is explained.
    #[serde(flatten)]
    pub loss: Loss,
}

/// A trajectory at the end of the run.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Flow {
    /// The trajectory.
    pub trajectory: String,
    /// Structures its writer added over the whole run.
    pub added: u64,
    /// Samples its writer's cache held at the end.
    pub stored: usize,
    /// Its rate at the end, Hz.
    pub rate_hz: f64,
}

/// What a run showed, against its targets.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Verdict {
    /// The growth target, percent.
    pub target_percent: f64,
    /// Time of the baseline sample, seconds.
    pub baseline_t: f64,
    /// Time of the last sample, seconds.
    pub end_t: f64,
    /// Resident memory growth per process (judged).
    pub rss: Vec<Growth>,
    /// Private memory (`RssAnon`) growth per process: not judged, but it tells a leak
    /// of the process's own (heap) from shared pages it touched for the first time
    /// (`rss` − `anon`: a shared-memory pool's high-water mark rising).
    pub anon: Vec<Growth>,
    /// Growth of the domain's allocated shared memory.
    pub shm: Option<Growth>,
    /// Per trajectory, its last counters read.
    pub trajectories: Vec<Flow>,
    /// Every loss at the end, by trajectory and cause.
    pub losses: Vec<TrajectoryLoss>,
    /// The sum of the unexplained ones.
    pub unexplained: u64,
    /// Every target missed, one line each; empty when the run passed.
    pub missed: Vec<String>,
}

impl Verdict {
    /// True when every target was met.
    pub fn passed(&self) -> bool {
        self.missed.is_empty()
    }
}

/// Judges `samples` (in time order) with the baseline at the first sample at or after
/// `warmup` seconds, against growth under `target_percent`.
pub fn judge(samples: &[Sample], warmup: f64, target_percent: f64) -> Verdict {
    let mut missed = Vec::new();
    let (Some(first), Some(last)) = (samples.first(), samples.last()) else {
        return Verdict {
            target_percent,
            baseline_t: 0.0,
            end_t: 0.0,
            rss: Vec::new(),
            anon: Vec::new(),
            shm: None,
            trajectories: Vec::new(),
            losses: Vec::new(),
            unexplained: 0,
            missed: vec!["no sample was taken".to_owned()],
        };
    };
    let from = samples.iter().position(|s| s.t >= warmup);
    match from {
        None => missed.push(format!(
            "the run ended at {:.0} s, before the warm-up of {warmup:.0} s was over: nothing to compare",
            last.t
        )),
        Some(i) if i + 1 == samples.len() => {
            missed.push("one sample after the warm-up: nothing to compare".to_owned());
        }
        Some(_) => {}
    }
    let from = from.unwrap_or(samples.len() - 1);
    let after = &samples[from..];
    let baseline = &samples[from];

    let (mut rss, mut anon) = (Vec::new(), Vec::new());
    for (name, p) in &last.processes {
        let points: Vec<(f64, u64)> =
            after.iter().filter_map(|s| Some((s.t, s.processes.get(name)?.rss))).collect();
        let private: Vec<(f64, u64)> =
            after.iter().filter_map(|s| Some((s.t, s.processes.get(name)?.anon))).collect();
        if !baseline.processes.contains_key(name) {
            missed.push(format!("{name} was not measured at the baseline ({:.0} s)", baseline.t));
        }
        let restarts =
            p.restarts.saturating_sub(first.processes.get(name).map_or(0, |f| f.restarts));
        if restarts > 0 {
            missed.push(format!("{name} restarted {restarts} times during the run"));
        } else if first.processes.get(name).is_some_and(|f| f.pid != p.pid) {
            missed.push(format!("{name} changed pid during the run"));
        }
        rss.extend(Growth::of(name, &points, target_percent));
        anon.extend(Growth::of(name, &private, target_percent));
    }
    for name in first.processes.keys().filter(|n| !last.processes.contains_key(*n)) {
        missed.push(format!("{name} was not measured at the end"));
    }
    for g in rss.iter().filter(|g| !g.within) {
        missed.push(format!(
            "{} grew {:.2} % (from {} to {} bytes)",
            g.what, g.percent, g.baseline, g.end
        ));
    }

    // A measurement that failed is no figure, and a failed check.
    let failed = after.iter().filter(|s| s.shm_failed).count();
    if failed > 0 {
        missed.push(format!(
            "the shared memory could not be measured at {failed} of {} samples",
            after.len()
        ));
    }
    let shm_points: Vec<(f64, u64)> =
        after.iter().filter(|s| !s.shm_failed).map(|s| (s.t, s.shm.allocated)).collect();
    let shm = Growth::of("shared memory", &shm_points, target_percent);
    if let Some(g) = shm.as_ref().filter(|g| !g.within) {
        missed.push(format!(
            "shared memory grew {:.2} % (from {} to {} bytes)",
            g.percent, g.baseline, g.end
        ));
    }

    let counted = samples.iter().rev().find(|s| !s.trajectories.is_empty());
    let mut losses = Vec::new();
    let mut trajectories = Vec::new();
    match counted {
        None => missed.push("no trajectory counters could be read".to_owned()),
        Some(end) => {
            let at_baseline = after.iter().find(|s| !s.trajectories.is_empty()).unwrap_or(end);
            for (name, c) in &end.trajectories {
                trajectories.push(Flow {
                    trajectory: name.clone(),
                    added: c.added,
                    stored: c.stored,
                    rate_hz: c.rate_hz,
                });
                let before = at_baseline.trajectories.get(name).map_or(0, |b| b.added);
                if c.added <= before && end.t > at_baseline.t {
                    missed.push(format!(
                        "{name} added nothing from {:.0} s to {:.0} s",
                        at_baseline.t, end.t
                    ));
                }
                losses.extend(
                    c.losses
                        .iter()
                        .map(|l| TrajectoryLoss { trajectory: name.clone(), loss: l.clone() }),
                );
            }
        }
    }
    let unexplained: u64 = losses.iter().filter(|l| !l.loss.explained).map(|l| l.loss.count).sum();
    if unexplained > 0 {
        missed.push(format!("{unexplained} unexplained losses"));
    }
    Verdict {
        target_percent,
        baseline_t: baseline.t,
        end_t: last.t,
        rss,
        anon,
        shm,
        trajectories,
        losses,
        unexplained,
        missed,
    }
}

#[cfg(test)]
mod tests {
    use super::super::probe::ShmUse;
    use super::super::sample::{Counts, ProcessSample};
    use super::*;

    /// A run of `n` samples a second apart: one process whose memory is `rss(t)`,
    /// shared memory `shm(t)`, one trajectory adding 30 a second.
    fn run(n: usize, rss: impl Fn(f64) -> u64, shm: impl Fn(f64) -> u64) -> Vec<Sample> {
        (0..n)
            .map(|i| {
                let t = i as f64;
                let mut s = Sample { t, ..Sample::default() };
                s.processes.insert(
                    "coordinator".into(),
                    ProcessSample { pid: 7, rss: rss(t), anon: rss(t) / 2, restarts: 0 },
                );
                s.shm = ShmUse { files: 4, allocated: shm(t), apparent: 1 << 30 };
                let counts =
                    Counts { added: 30 * i as u64, stored: 5, rate_hz: 30.0, losses: Vec::new() };
                s.trajectories.insert("images".into(), counts);
                s
            })
            .collect()
    }

    #[test]
    fn a_failed_shared_memory_measurement_is_a_missed_check_not_a_zero() {
        let mut samples = run(20, |_| 100 << 20, |_| 10 << 20);
        samples[15].shm = ShmUse::default();
        samples[15].shm_failed = true;
        let v = judge(&samples, 2.0, 10.0);
        assert!(
            v.missed.iter().any(|m| m.contains("could not be measured at 1 of")),
            "{:?}",
            v.missed
        );
        // The zero did not enter the growth figure.
        assert_eq!(v.shm.as_ref().map(|g| g.percent), Some(0.0));
    }

    #[test]
    fn growth_is_relative_to_the_baseline() {
        assert_eq!(growth_percent(200, 202), 1.0);
        assert_eq!(growth_percent(200, 190), -5.0);
        assert_eq!(growth_percent(0, 0), 0.0);
        assert!(growth_percent(0, 1).is_infinite());
    }

    #[test]
    fn flat_after_the_warm_up_passes() {
        // Memory fills during the warm-up (10 s here), then stays.
        let samples = run(30, |t| if t < 10.0 { 1000 * t as u64 } else { 10_000 }, |_| 4096);
        let v = judge(&samples, 10.0, 1.0);
        assert!(v.passed(), "{:?}", v.missed);
        assert_eq!(v.baseline_t, 10.0);
        assert_eq!((v.rss[0].percent, v.anon[0].percent), (0.0, 0.0));
        assert_eq!(v.trajectories.len(), 1);
        assert_eq!((v.trajectories[0].added, v.trajectories[0].stored), (29 * 30, 5));
    }

    #[test]
    fn slow_growth_after_the_warm_up_fails() {
        let samples = run(30, |t| 10_000 + 10 * t as u64, |t| 4096 + 4096 * (t as u64 / 20));
        let v = judge(&samples, 10.0, 1.0);
        assert!(!v.rss[0].within);
        assert!((v.rss[0].percent - 1.88).abs() < 0.01, "{}", v.rss[0].percent);
        assert_eq!(v.shm.as_ref().map(|g| g.percent), Some(100.0));
        assert_eq!(v.missed.len(), 2, "{:?}", v.missed);
    }

    #[test]
    fn unexplained_losses_restarts_and_stalls_fail() {
        let mut samples = run(5, |_| 100, |_| 100);
        let last = samples.last_mut().unwrap();
        last.processes.get_mut("coordinator").unwrap().restarts = 1;
        let images = last.trajectories.get_mut("images").unwrap();
        images.added = 0;
        images.losses = vec![
            Loss { cause: "lost".into(), count: 5, explained: true },
            Loss { cause: "rejected_malformed".into(), count: 2, explained: false },
        ];
        let v = judge(&samples, 1.0, 1.0);
        assert_eq!(v.unexplained, 2);
        assert_eq!(v.losses.len(), 2);
        assert_eq!(v.missed.len(), 3, "{:?}", v.missed);
    }

    #[test]
    fn a_run_shorter_than_the_warm_up_has_nothing_to_compare() {
        let v = judge(&run(3, |_| 100, |_| 100), 60.0, 1.0);
        assert_eq!(v.baseline_t, 2.0);
        assert!(!v.passed());
        assert!(!judge(&[], 60.0, 1.0).passed());
    }
}
