//! The conformance suite: every rule of the ESGM interface, generic over the runtime.
//!
//! Each function takes a fresh [`Harness`]; [`crate::conformance_tests!`] makes one
//! `#[test]` per function. Waits go through [`crate::wait_for`] with [`WAIT`], so a
//! runtime that misbehaves fails the test instead of hanging it.

pub mod computed;
pub mod lifecycle;
pub mod operators;
pub mod primitive;
pub mod sampled;

use std::time::Duration;

use esgm_core::{
    EntityStructure, EntityStructureType, EntityTrajectoryStructure, Esgm, Time, ValueSort,
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
pub fn x_of(es: &EntityStructure) -> Option<f64> {
    es.get("x").and_then(|v| v.as_double())
}

/// Waits until `t` stores `n` samples; fails the test otherwise.
pub fn wait_stored<T: EntityTrajectoryStructure>(t: &T, n: usize) {
    let ok = crate::wait_for(WAIT, || t.stats().map(|s| s.stored) == Ok(n));
    assert!(ok, "`{}` never stored {n} samples (has {:?})", t.name(), t.stats().map(|s| s.stored));
}

/// Expands to one `#[test]` per conformance function, each on a fresh harness made by
/// `$make()`.
#[macro_export]
macro_rules! conformance_tests {
    ($make:expr) => {
        $crate::conformance_tests!(@each $make;
            primitive::types_create_get_destroy,
            primitive::primitive_add_and_query,
            primitive::primitive_policy_is_enforced,
            primitive::subscriptions_in_add_order_with_replay,
            primitive::violations_are_delivered_and_counted,
            primitive::held_samples_are_released_on_time,
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
            lifecycle::destroy_and_reuse_a_name,
            lifecycle::re_pointing_keeps_subscribers_and_handles,
            lifecycle::external_adds_only_on_primitive,
            lifecycle::in_use_sensors_and_units_cannot_be_removed,
            lifecycle::stats_memory_ping_reset_log_level,
            operators::sync_exact,
            operators::sync_approximate,
            operators::merge_interleaves_inputs,
            operators::merge_keeps_add_order_across_inputs,
            operators::sampled_generator_and_state,
            operators::sampled_temporal_function,
        );
    };
    (@each $make:expr; $($module:ident :: $test:ident),* $(,)?) => {
        $(
            #[test]
            fn $test() {
                let h = $make();
                $crate::conformance::$module::$test(&h);
            }
        )*
    };
}
