//! The conformance suite: every rule of the ESGM interface, generic over the runtime.
//!
//! Each function takes a fresh [`Harness`]; [`crate::conformance_tests!`] makes one
//! `#[test]` per function. Waits go through [`crate::wait_for`] with [`WAIT`], so a
//! runtime that misbehaves fails the test instead of hanging it.
//!
//! A test writes through [`Harness::esgm`] and checks what a user sees through handles
//! of [`Harness::reader`] ([`read`]): on the shared-memory runtime that is another
//! location, so every semantic is checked across the process boundary. What crosses
//! it arrives asynchronously: a reader-side check first waits for it
//! ([`wait_visible`], [`wait_stored`], [`crate::wait_for`]). Tests whose point is the
//! writer's own outcome (an error returned by an add) check it on the writer's handle
//! and what the reader sees of it as well.

pub mod api;
pub mod computed;
pub mod domain;
pub mod lifecycle;
pub mod lineage;
pub mod operators;
pub mod primitive;
pub mod queries;
pub mod sampled;
pub mod why;

use std::time::Duration;

use esgm_core::{
    EntityStructure, EntityStructureType, EntityTrajectoryStructure, Esgm, QueryError, Time,
    ValueSort,
};

use crate::Harness;

/// How long a test waits for the runtime before failing.
pub const WAIT: Duration = Duration::from_secs(10);

/// Registers the test type `Reading { x: Double, n: Long }`.
pub fn register_reading<H: Harness>(h: &H) {
    h.esgm()
        .create_entity_structure_type(
            "Reading",
            EntityStructureType::new("Reading")
                .attr("x", ValueSort::Double)
                .attr("n", ValueSort::Long),
        )
        .expect("register Reading");
}

/// A `Reading` valid (and created) at `vt`.
pub fn reading(vt: Time, x: f64) -> EntityStructure {
    EntityStructure::new("r", vt, vt).with("x", x).with("n", x as i64)
}

/// The `x` of a structure, for compact assertions.
pub fn x_of(es: &esgm_core::SharedStructure) -> Option<f64> {
    es.get("x").and_then(|v| v.as_double())
}

/// The reading side's handle on the trajectory `name`: the writer's trajectory as
/// another location sees it (on the shared-memory runtime, a replica fed across the
/// boundary).
pub fn read<H: Harness>(h: &H, name: &str) -> <H::E as Esgm>::Trajectory {
    h.reader()
        .get_entity_trajectory_structure(name)
        .unwrap_or_else(|e| panic!("the reader cannot open `{name}`: {e}"))
}

/// Every stored sample of `t` as (add time, structure), oldest first: what two
/// locations must agree on (query times differ by design).
pub fn contents<T: EntityTrajectoryStructure>(
    t: &T,
) -> Result<Vec<(Time, EntityStructure)>, QueryError> {
    let all = t.get_between(Time::MIN, Time::MAX)?;
    Ok(all.iter().map(|s| (s.add_time, s.structure.to_structure())).collect())
}

/// Waits until `reader` stores exactly what `writer` stores (the same structures with
/// the same add times, in order); fails the test otherwise. Replication across
/// locations is asynchronous: call it before a reader-side check of what the writer
/// did (an empty writer is waited for too, e.g. after a reset).
pub fn wait_visible<T: EntityTrajectoryStructure>(writer: &T, reader: &T) {
    let ok = crate::wait_for(WAIT, || match (contents(writer), contents(reader)) {
        (Ok(w), Ok(r)) => w == r,
        _ => false,
    });
    assert!(
        ok,
        "the reader of `{}` never caught up with its writer:\n writer {:?}\n reader {:?}",
        writer.name(),
        contents(writer),
        contents(reader)
    );
}

/// Waits until `t` stores `n` samples; fails the test otherwise.
pub fn wait_stored<T: EntityTrajectoryStructure>(t: &T, n: usize) {
    let ok = crate::wait_for(WAIT, || t.stats().map(|s| s.stored) == Ok(n));
    assert!(ok, "`{}` never stored {n} samples (has {:?})", t.name(), t.stats().map(|s| s.stored));
}

/// Expands to one `#[test]` per conformance function, each on a fresh harness made by
/// `$make()`, for the runtime named by `$runtime` (`in_process` or `shm`).
///
/// An entry may carry `[shm: "reason"]`: a semantic the shared-memory runtime does not
/// meet yet across the boundary. Its test stays, marked `#[ignore = "reason"]` on that
/// runtime only (`cargo test -- --ignored` runs it), until the runtime is fixed.
#[macro_export]
macro_rules! conformance_tests {
    ($runtime:ident, $make:expr) => {
        $crate::conformance_tests!(@each $runtime, $make;
            api::get_latest_vtime_is_the_most_current,
            api::types_structures_and_stats_by_name,
            domain::reset_from_any_side_reaches_writer_and_readers,
            domain::e7_acts_on_the_system_from_either_side,
            domain::flush_waits_for_units_and_replicas,
            domain::flush_gives_up_at_its_deadline,
            primitive::types_create_get_destroy,
            primitive::primitive_add_and_query,
            primitive::primitive_policy_is_enforced,
            primitive::stats_agree_across_locations,
            primitive::subscriptions_in_add_order_with_replay,
            primitive::violations_are_delivered_and_counted,
            primitive::held_samples_are_released_on_time,
            primitive::adds_through_the_reader_reach_the_writer,
            primitive::blocking_adds_through_the_reader_get_the_writers_outcome,
            queries::the_reader_answers_every_query_as_the_writer,
            queries::extreme_valid_times_are_queried,
            queries::linear_interpolates_sequences_element_wise_or_says_it_did_not,
            sampled::sampling_periods_and_from_to,
            sampled::one_sensor_many_periods,
            sampled::sensor_errors_and_panics_are_counted,
            sampled::late_sensor_is_a_delay_violation,
            sampled::sampled_cache_keeps_the_last_n,
            computed::inputs_in_order_once_all_have_one,
            computed::value_not_available_means_no_output,
            computed::three_level_chain,
            computed::unit_panic_is_isolated,
            computed::unit_output_is_type_checked,
            computed::inputs_are_checked_at_creation,
            computed::computed_policy_applies,
            computed::reset_inputs_are_forgotten,
            lifecycle::unknown_names_get_the_seed_errors,
            lifecycle::duplicate_registrations_are_refused,
            lifecycle::destroy_and_reuse_a_name,
            lifecycle::destroyed_names_are_gone_for_readers,
            lifecycle::destroy_through_the_reader,
            lifecycle::re_pointing_keeps_subscribers_and_handles,
            lifecycle::external_adds_only_on_primitive,
            lifecycle::in_use_sensors_and_units_cannot_be_removed,
            lifecycle::stats_memory_ping_reset_log_level,
            operators::sync_exact,
            operators::sync_approximate,
            operators::sync_epsilon,
            operators::merge_rules_are_checked_against_the_type,
            operators::merge_interleaves_inputs,
            operators::merge_keeps_add_order_across_inputs,
            operators::sampled_generator_and_state,
            operators::sampled_temporal_function,
            lineage::a_three_stage_pipeline_names_its_inputs,
            lineage::operators_name_their_inputs,
            lineage::a_trace_names_what_is_gone,
            why::why_names_what_the_unit_returned,
            why::why_names_the_input_it_waits_for,
            why::why_names_the_constraint_that_dropped,
            why::why_names_what_a_sync_waits_for,
            why::why_names_each_inputs_sync_drops,
            why::why_names_missed_sample_points,
            why::why_names_what_the_sensor_returned,
        );
    };
    (@each $runtime:ident, $make:expr;
        $($module:ident :: $test:ident $([$($mark:tt)*])?),* $(,)?) => {
        $(
            $crate::conformance_tests!(@test $runtime, $make, $module, $test; $($($mark)*)?);
        )*
    };
    (@test shm, $make:expr, $module:ident, $test:ident; shm: $reason:literal) => {
        #[test]
        #[ignore = $reason]
        fn $test() {
            let h = $make();
            $crate::conformance::$module::$test(&h);
        }
    };
    (@test $runtime:ident, $make:expr, $module:ident, $test:ident; $($mark:tt)*) => {
        #[test]
        fn $test() {
            let h = $make();
            $crate::conformance::$module::$test(&h);
        }
    };
}
