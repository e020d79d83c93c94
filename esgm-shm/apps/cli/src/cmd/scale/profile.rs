//! The synthetic robot `esgm scale` runs: which trajectories there are, at what rate,
//! which process writes each and which read it. Deterministic, so two runs of one
//! profile are the same system.
//!
//! The default is a mobile base's size: 300 trajectories in 60 processes, with
//! - `tf`, a transform stream at 100 Hz read by every process (or `--readers` of them);
//! - ten 640×480 RGB cameras (`cam0`…) at 30 Hz, each read by 3 processes;
//! - the rest small structures (`s0`…, `RobotState`) at 10–50 Hz with 1–4 readers each.

use serde::{Deserialize, Serialize};

/// Kinds of trajectory, each with its own latency figures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Class {
    /// The transform stream every process reads.
    Tf,
    /// A camera's images.
    Image,
    /// A small structure.
    Small,
}

impl Class {
    /// Every class, in report order.
    pub const ALL: [Class; 3] = [Class::Tf, Class::Image, Class::Small];

    /// The library type its structures have.
    pub fn type_name(self) -> &'static str {
        match self {
            Class::Tf | Class::Small => "RobotState",
            Class::Image => "Image",
        }
    }

    /// Its name in reports.
    pub fn label(self) -> &'static str {
        match self {
            Class::Tf => "tf",
            Class::Image => "image 640x480",
            Class::Small => "small",
        }
    }
}

/// The size of the synthetic robot (`esgm scale`, `esgm chaos`).
#[derive(Debug, Clone, clap::Args)]
pub struct Size {
    /// Trajectories of the synthetic robot.
    #[arg(long, default_value_t = 300)]
    pub trajectories: usize,
    /// Processes of the synthetic robot.
    #[arg(long, default_value_t = 60)]
    pub processes: usize,
}

/// One trajectory of the profile.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Planned {
    /// Its name.
    pub name: String,
    /// Its class.
    pub class: Class,
    /// Structures per second its writer adds.
    pub hz: f64,
    /// The process that writes it.
    pub writer: usize,
    /// The processes that read it (never its writer).
    pub readers: Vec<usize>,
}

/// A whole synthetic robot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Profile {
    /// Processes, numbered from 0.
    pub processes: usize,
    /// Its trajectories.
    pub trajectories: Vec<Planned>,
}

/// Cameras of the default profile.
const CAMERAS: usize = 10;
/// Readers of each camera.
const CAMERA_READERS: usize = 3;

impl Profile {
    /// The profile of `trajectories` in `processes`, `tf` read by `tf_readers`
    /// processes (at most every other one).
    pub fn new(trajectories: usize, processes: usize, tf_readers: usize) -> anyhow::Result<Self> {
        if processes < 2 {
            anyhow::bail!("--processes must be at least 2 (a writer and a reader)");
        }
        if trajectories == 0 {
            anyhow::bail!("--trajectories must be at least 1");
        }
        let others = |writer: usize, n: usize, seed: usize| -> Vec<usize> {
            // n distinct processes other than the writer, spread by a stride.
            let n = n.min(processes - 1);
            let stride =
                [7, 11, 13, 17, 19, 23].into_iter().find(|s| processes % s != 0).unwrap_or(1);
            let mut out = Vec::with_capacity(n);
            let mut p = (writer + 1 + seed) % processes;
            while out.len() < n {
                if p != writer && !out.contains(&p) {
                    out.push(p);
                }
                // A prime stride that does not divide the count visits every process.
                p = (p + stride) % processes;
            }
            out
        };
        let mut planned = vec![Planned {
            name: "tf".into(),
            class: Class::Tf,
            hz: 100.0,
            writer: 0,
            readers: others(0, tf_readers, 0),
        }];
        let cameras = CAMERAS.min(trajectories.saturating_sub(1));
        for c in 0..cameras {
            let writer = 1 + c % (processes - 1);
            planned.push(Planned {
                name: format!("cam{c}"),
                class: Class::Image,
                hz: 30.0,
                writer,
                readers: others(writer, CAMERA_READERS, c),
            });
        }
        for s in 0..trajectories.saturating_sub(1 + cameras) {
            let writer = (s * 7 + 3) % processes;
            planned.push(Planned {
                name: format!("s{s}"),
                class: Class::Small,
                hz: 10.0 + (s * 13 % 41) as f64,
                writer,
                readers: others(writer, 1 + s % 4, s),
            });
        }
        // Every process reads something (the writer of `tf` included): a robot's
        // processes read as well as write.
        for p in 0..processes {
            if planned.iter().any(|t| t.readers.contains(&p)) {
                continue;
            }
            let fits = |t: &Planned| t.class == Class::Small && t.readers.len() < 4;
            let pick = planned
                .iter()
                .rposition(|t| t.writer != p && fits(t))
                .or_else(|| planned.iter().rposition(|t| t.writer != p));
            if let Some(t) = pick.and_then(|i| planned.get_mut(i)) {
                t.readers.push(p);
            }
        }
        Ok(Profile { processes, trajectories: planned })
    }

    /// The trajectories process `p` writes.
    pub fn written_by(&self, p: usize) -> impl Iterator<Item = &Planned> {
        self.trajectories.iter().filter(move |t| t.writer == p)
    }

    /// The trajectories process `p` reads.
    pub fn read_by(&self, p: usize) -> impl Iterator<Item = &Planned> {
        self.trajectories.iter().filter(move |t| t.readers.contains(&p))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn the_default_profile_is_a_mobile_base() {
        let p = Profile::new(300, 60, 59).unwrap();
        assert_eq!(p.trajectories.len(), 300);
        let tf = &p.trajectories[0];
        assert_eq!((tf.name.as_str(), tf.readers.len()), ("tf", 59));
        let cams: Vec<_> = p.trajectories.iter().filter(|t| t.class == Class::Image).collect();
        assert_eq!(cams.len(), 10);
        assert!(cams.iter().all(|c| c.readers.len() == 3 && c.hz == 30.0));
        for t in &p.trajectories {
            assert!(!t.readers.contains(&t.writer), "{} reads itself", t.name);
            let mut r = t.readers.clone();
            r.dedup();
            assert_eq!(r.len(), t.readers.len(), "{}: distinct readers", t.name);
            if t.class == Class::Small {
                assert!((1..=4).contains(&t.readers.len()) && (10.0..=50.0).contains(&t.hz));
            }
        }
        assert!((0..60).all(|w| p.written_by(w).count() >= 1), "every process writes");
        assert!((0..60).all(|r| p.read_by(r).count() >= 1), "every process reads");
    }

    #[test]
    fn small_profiles_stay_well_formed() {
        let p = Profile::new(3, 2, 5).unwrap();
        assert_eq!(p.trajectories.len(), 3);
        assert!(p.trajectories.iter().all(|t| t.readers == vec![1 - t.writer]));
        assert!(Profile::new(10, 1, 1).is_err());
    }
}
