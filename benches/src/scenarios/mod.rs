//! Every scenario of `esgm-bench`, one per file, in run order: a baseline comes before
//! the scenarios compared with it.
//!
//! In-process (issue 3), on [`esgm_core::InProcessEsgm`] with the system clock and
//! real threads:
//! - [`inproc_echo`]: the ping-pong the hop scenarios share;
//! - [`inproc_floor_crossbeam`]: the floor, a raw crossbeam channel ping-pong;
//! - [`inproc_hop_small`] and [`inproc_hop_image`]: one add → subscriber hop of a
//!   small structure and of a 640×480 RGB image;
//! - [`inproc_chain3`]: a three-unit computed chain, against a single hop;
//! - [`inproc_sampling_jitter`]: lateness of a 100 Hz sampled trajectory.

pub mod inproc_chain3;
pub mod inproc_echo;
pub mod inproc_floor_crossbeam;
pub mod inproc_hop_image;
pub mod inproc_hop_small;
pub mod inproc_sampling_jitter;

use crate::scenario::Scenario;

/// Every scenario, in run order.
pub fn all() -> Vec<Box<dyn Scenario>> {
    vec![
        Box::new(inproc_floor_crossbeam::InprocFloorCrossbeam),
        Box::new(inproc_hop_small::InprocHopSmall),
        Box::new(inproc_hop_image::InprocHopImage),
        Box::new(inproc_chain3::InprocChain3),
        Box::new(inproc_sampling_jitter::InprocSamplingJitter),
    ]
}

#[cfg(test)]
mod tests {
    use std::collections::HashSet;

    use super::*;

    #[test]
    fn names_are_unique_and_baselines_run_first() {
        let all = all();
        let mut seen = HashSet::new();
        for s in &all {
            assert!(seen.insert(s.name()), "duplicate scenario {}", s.name());
        }
        assert_eq!(all[0].name(), inproc_floor_crossbeam::NAME);
    }
}
