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
//!
//! Cross-process (issue 4): the measuring process against a peer process — `esgm-bench`
//! itself, started again in a hidden peer role ([`crate::peer_role`]) — one per
//! measurement, in service domains and socket names unique to it (they hold the
//! measuring process's id). Latency is half a round trip; `spin` rows busy-poll,
//! `event` rows block, and esgm adds its default strategy as `-default` rows
//! ([`crate::wait_mode`]).
//! - [`ipc_floor_iceoryx2`]: the floor, raw iceoryx2 with a 64-byte message, and the
//!   same on the thread-safe service type esgm uses (`floor-iceoryx2-threadsafe`);
//! - [`ipc_floor_futex`]: `floor-futex`, the wake-up alone through a futex word in
//!   shared memory (issue 27), and `floor-futex-paced`, the same once per camera
//!   frame: the floor of a pipeline stage;
//! - [`ipc_uds_small`] and [`ipc_uds_image`]: the baselines, the codec's bytes through a
//!   Unix socket ([`ipc_uds_echo`], [`ipc_uds_frames`]);
//! - [`ipc_esgm_small`] and [`ipc_esgm_image`]: esgm-shm's trajectories, a small
//!   structure and an image written in place ([`ipc_esgm_echo`]); what they carry is in
//!   [`ipc_payload`], their node in [`ipc_node`].
//!
//! Order: the floor, then `uds-small` (the baseline of `esgm-small-default`), then the
//! esgm scenarios, then `uds-image` (compared with `esgm-image`).
//!
//! The benchmarks issue (6) adds, after them:
//! - the peers [`zenoh_peer`] (`zenoh-small`, `zenoh-image`; cargo feature `zenoh`,
//!   measured in `zenoh_echo`) and [`ros1_peer`] (`ros1-small`, `ros1-image`; a roscpp
//!   program built by `benches/ros1/build.sh`), each skipped with the way to run it
//!   when not built;
//! - [`ipc_connect`]: `connect-small`, `connect-image`, the same hops through the API a
//!   user calls (`esgm_shm` `connect` on both sides, [`ipc_connect_echo`]), compared
//!   with `esgm-small`, `ros1-small` and `zenoh-small` (so after them);
//! - [`ipc_throughput`]: `throughput-1x1`, `throughput-1x4`, lossless, losses counted;
//! - [`ipc_query`]: `query-<op>-<n>` on a `connect` replica holding 10^3 and 10^6;
//! - [`ipc_pipeline`]: `pipeline-<stage>`, the tutorial across six processes;
//! - [`ipc_memory`]: resident and shared memory, into the report's `memory` section.
//!
//! The scale issue (23) adds, after `pipeline-*`:
//! - [`ipc_scale`]: `scale-{connect,first-add,idle}-<n>` for domains of 10, 100 and
//!   1,000 trajectories, against the domain of 10, with memory rows;
//! - [`ipc_fanout`]: `fanout-<k>`, one writer and k reader connections, until the last
//!   reader holds the structure, against `fanout-1`;
//! - [`ros1_fanout`]: `ros1-fanout-<k>`, the same through roscpp with k reader
//!   processes, against `fanout-<k>` (when the ROS 1 peer is built).
//!
//! Issue 27 adds, after the ROS 1 peer, [`dora_peer`]: `dora-small` and `dora-image`,
//! the same ping-pong between two Rust nodes on `dora-node-api` through dora's daemon
//! (`dora run`, [`dora_run`]; built by `benches/dora/build.sh`, skipped with that
//! instruction when not built), against `esgm-small` and `esgm-image`.
//!
//! The C and C++ issue (37) adds, after `connect-*`:
//! - [`ipc_cpp`]: `cpp-small` and `cpp-image`, the `connect` rows' hops made by two C++
//!   processes through esgm's C ABI (`benches/cpp/cpp_pingpong.cpp`, built on first use
//!   by [`cpp_program`]), held to `connect-small` and `connect-image`;
//! - [`iceoryx_c_peer`]: `iceoryx-c-small` and `iceoryx-c-image`, a C peer: the same
//!   payloads between two C processes on classic iceoryx's C binding, with a private
//!   RouDi ([`iceoryx_roudi`]; built by `benches/iceoryx/build.sh`, skipped with that
//!   instruction when not built), against the `cpp-*` rows.
//!
//! Both run their pair of programs through [`program_pair`].
//!
//! The Python issue (26) adds, after `connect-*`, [`python_peer`]: `python-small` and
//! `python-image` (esgm's Python package, process to process) beside the same hop
//! through iceoryx2's (`python-iceoryx2-*`) and Zenoh's (`python-zenoh-*`) Python
//! packages, run by a venv the bench makes ([`crate::python_env`]).
//!
//! The ROS 2 issue (25) adds, after `bridge-*`, [`ros2_peer`]: `ros2-raw-small` and
//! `ros2-raw-image` (a raw DDS hop between two processes on ros2-client), then
//! `ros2-export-*` and `ros2-import-*` through the `esgm-ros2` bridge, against them
//! (cargo feature `ros2`; DDS only inside a loopback-only network namespace).
//!
//! The ROS user's first hour (issue 40) adds [`cli_query`]: every CLI query verb as a
//! whole `esgm` process, in a domain of 10 and of 1,000 trajectories.
//!
//! The silent-failures issue (24) adds [`control_churn`]: `control-ping` and
//! `control-ping-churn`, a client's call to the coordinator while others churn.
//!
//! The reference-system issue (38) adds, after `control-*`, [`refsys`]: the Autoware
//! reference system on `refsys-ros1` and `refsys-ros2` (the peers, first: esgm's targets
//! compare with them) and then `refsys-esgm` and `refsys-esgm-procs`, each in upstream's
//! default timing and without work (`-nowork`), with CPU and planner rows, and
//! `refsys-esgm-work`, one node's calibrated work.
//!
//! The recordings issue (14) adds, after `pipeline-*` (before `memory`):
//! - [`record_small`]: `record-small`, `record-small-none`, `RobotState`s from another
//!   process recorded by the `Recorder` (zstd, none): structures/s in batches, losses
//!   with their causes;
//! - [`file_write_image`]: `file-write-image`, the baseline of `record-image`: the same
//!   bytes per frame through a plain `std::fs::File` loop;
//! - [`record_image`]: `record-image`, 640×480 RGB frames rendered into loans and
//!   recorded uncompressed: MB/s, against `file-write-image`;
//! - [`replay_max`]: `replay-max`, `replay-max-connect`, a 10^6-structure recording
//!   replayed as fast as possible into an in-process ESGM and a `connect` domain.
//!
//! `BENCHMARKS.md` at the repository root has a run's results and what they mean.

pub mod bridge;
pub mod cli_query;
pub mod control_churn;
pub mod cpp_program;
pub mod dora_peer;
pub mod dora_run;
pub mod file_write_image;
pub mod iceoryx_c_peer;
pub mod iceoryx_roudi;
pub mod inproc_chain3;
pub mod inproc_echo;
pub mod inproc_floor_crossbeam;
pub mod inproc_hop_image;
pub mod inproc_hop_small;
pub mod inproc_sampling_jitter;
pub mod ipc_connect;
pub mod ipc_connect_echo;
pub mod ipc_cpp;
pub mod ipc_esgm_echo;
pub mod ipc_esgm_image;
pub mod ipc_esgm_small;
pub mod ipc_fanout;
pub mod ipc_floor_futex;
pub mod ipc_floor_iceoryx2;
pub mod ipc_memory;
pub mod ipc_node;
pub mod ipc_payload;
pub mod ipc_pipeline;
pub mod ipc_query;
pub mod ipc_scale;
pub mod ipc_throughput;
pub mod ipc_uds_echo;
pub mod ipc_uds_frames;
pub mod ipc_uds_image;
pub mod ipc_uds_small;
pub mod peer_rows;
pub mod pipeline_woken;
pub mod program_pair;
pub mod python_peer;
pub mod record_image;
pub mod record_small;
pub mod refsys;
pub mod replay_max;
pub mod ros1_fanout;
pub mod ros1_peer;
#[cfg(feature = "ros2")]
pub mod ros2_dds;
#[cfg(feature = "ros2")]
pub mod ros2_hop;
pub mod ros2_peer;
#[cfg(feature = "ros2")]
pub mod ros2_process;
#[cfg(feature = "zenoh")]
pub mod zenoh_echo;
pub mod zenoh_peer;

use crate::scenario::Scenario;

/// Every scenario, in run order.
pub fn all() -> Vec<Box<dyn Scenario>> {
    vec![
        Box::new(inproc_floor_crossbeam::InprocFloorCrossbeam),
        Box::new(inproc_hop_small::InprocHopSmall),
        Box::new(inproc_hop_image::InprocHopImage),
        Box::new(inproc_chain3::InprocChain3),
        Box::new(inproc_sampling_jitter::InprocSamplingJitter),
        Box::new(ipc_floor_iceoryx2::FloorIceoryx2::PLAIN),
        Box::new(ipc_floor_iceoryx2::FloorIceoryx2::THREADSAFE),
        Box::new(ipc_floor_futex::FloorFutex::BACK_TO_BACK),
        Box::new(ipc_floor_futex::FloorFutex::PACED),
        Box::new(ipc_uds_small::UdsSmall),
        Box::new(ipc_esgm_small::EsgmSmall),
        Box::new(ipc_esgm_image::EsgmImage),
        Box::new(ipc_uds_image::UdsImage),
        Box::new(zenoh_peer::Zenoh::SMALL),
        Box::new(zenoh_peer::Zenoh::IMAGE),
        Box::new(zenoh_peer::Zenoh::TCP_SMALL),
        Box::new(zenoh_peer::Zenoh::TCP_IMAGE),
        Box::new(ros1_peer::Ros1::SMALL),
        Box::new(ros1_peer::Ros1::IMAGE),
        Box::new(dora_peer::Dora::SMALL),
        Box::new(dora_peer::Dora::IMAGE),
        Box::new(ipc_connect::Connect::SMALL),
        Box::new(ipc_connect::Connect::SMALL_PACED),
        Box::new(ipc_connect::Connect::IMAGE),
        Box::new(ipc_connect::Connect::SMALL_VOLATILE),
        Box::new(ipc_connect::Connect::IMAGE_VOLATILE),
        Box::new(ipc_cpp::Cpp::SMALL),
        Box::new(ipc_cpp::Cpp::IMAGE),
        Box::new(iceoryx_c_peer::IceoryxC::SMALL),
        Box::new(iceoryx_c_peer::IceoryxC::IMAGE),
        Box::new(python_peer::Python::ICEORYX2_SMALL),
        Box::new(python_peer::Python::ICEORYX2_IMAGE),
        Box::new(python_peer::Python::SMALL),
        Box::new(python_peer::Python::IMAGE),
        Box::new(python_peer::Python::ZENOH_SMALL),
        Box::new(python_peer::Python::ZENOH_IMAGE),
        Box::new(bridge::Bridge::SMALL),
        Box::new(bridge::Bridge::IMAGE),
        Box::new(ros2_peer::Ros2::RAW_SMALL),
        Box::new(ros2_peer::Ros2::RAW_IMAGE),
        Box::new(ros2_peer::Ros2::EXPORT_SMALL),
        Box::new(ros2_peer::Ros2::EXPORT_IMAGE),
        Box::new(ros2_peer::Ros2::IMPORT_SMALL),
        Box::new(ros2_peer::Ros2::IMPORT_IMAGE),
        Box::new(ipc_throughput::Throughput::ONE),
        Box::new(ipc_throughput::Throughput::FOUR),
        Box::new(ipc_query::Query::THOUSAND),
        Box::new(ipc_query::Query::MILLION),
        Box::new(ipc_pipeline::Pipeline),
        Box::new(ipc_scale::Scale::TEN),
        Box::new(ipc_scale::Scale::HUNDRED),
        Box::new(ipc_scale::Scale::THOUSAND),
        Box::new(ipc_fanout::Fanout::ONE),
        Box::new(ipc_fanout::Fanout::EIGHT),
        Box::new(ipc_fanout::Fanout::THIRTY_TWO),
        Box::new(ipc_fanout::Fanout::SIXTY_FOUR),
        Box::new(ros1_fanout::Ros1Fanout::ONE),
        Box::new(ros1_fanout::Ros1Fanout::EIGHT),
        Box::new(ros1_fanout::Ros1Fanout::THIRTY_TWO),
        Box::new(ros1_fanout::Ros1Fanout::SIXTY_FOUR),
        Box::new(control_churn::ControlChurn),
        Box::new(cli_query::CliQuery),
        Box::new(refsys::Refsys::ROS1),
        Box::new(refsys::Refsys::ROS2),
        Box::new(refsys::Refsys::ESGM),
        Box::new(refsys::Refsys::ESGM_PROCS),
        Box::new(record_small::RecordSmall),
        Box::new(file_write_image::FileWriteImage),
        Box::new(record_image::RecordImage),
        Box::new(replay_max::ReplayMax),
        Box::new(ipc_memory::Memory),
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

    #[test]
    fn the_cross_process_names_are_the_issues() {
        let names: Vec<_> = all().iter().map(|s| s.name()).collect();
        for name in [
            "floor-iceoryx2",
            "esgm-small",
            "esgm-image",
            "uds-small",
            "uds-image",
            "connect-small",
            "connect-image",
            "cpp-small",
            "cpp-image",
        ] {
            assert!(names.contains(&name), "{name} missing from {names:?}");
        }
    }

    #[test]
    fn targets_name_rows_of_scenarios_that_run_before_the_table() {
        let all = all();
        let position = |row: &str| {
            // A row is named for its scenario, possibly with a suffix (`-default`); when
            // two scenarios' names both prefix it (`refsys-esgm`, `refsys-esgm-procs`),
            // the row is the longer one's.
            all.iter()
                .enumerate()
                .filter(|(_, s)| row == s.name() || row.starts_with(&format!("{}-", s.name())))
                .max_by_key(|(_, s)| s.name().len())
                .map(|(i, _)| i)
        };
        for (i, s) in all.iter().enumerate() {
            for t in s.targets() {
                assert_eq!(position(&t.row), Some(i), "{t:?} is not a row of {}", s.name());
                for other in t.rows().skip(1) {
                    assert!(
                        position(other).is_some_and(|p| p <= i),
                        "{t:?}: {other} is no row of a scenario before (or of) {}",
                        s.name()
                    );
                }
            }
        }
    }
}
