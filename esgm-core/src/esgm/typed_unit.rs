//! Typed computational units: a unit that declares its input and output types, and
//! receives its inputs as values of them instead of positional samples.
//!
//! Why: a [`CompUnit`] gets `&[Sample]` and unpacks it by position, checking each
//! structure's type itself; a unit with two inputs did it twice (its `compute` and its
//! `compute_at`), and a mistake in the order is found at run time. A [`TypedUnit`]
//! names its inputs as a tuple of [`Entity`] types and its output as one: the adapter
//! ([`TypedUnitAdapter`], or [`TypedUnit::compute_samples`] for a unit that also keeps
//! its untyped form) checks the count, decodes every input and stamps the output, and
//! the input types a runtime registers come from the same tuple
//! ([`TypedUnit::input_types`]), so they cannot disagree. copper's `CuTask` declares
//! its inputs and outputs the same way.
//!
//! The untyped [`CompUnit`] stays for units whose types are known only at run time (a
//! moving average over any type a system file names).
//!
//! ```
//! use std::sync::Arc;
//! use std::time::{Duration, Instant};
//! use esgm_core::esgm::{Stamped, TypedUnit, TypedUnitAdapter};
//! use esgm_core::library::{Blob, DrivingDirection, RobotState};
//! use esgm_core::prelude::*;
//!
//! /// Steers straight at the blob, from the robot's pose.
//! struct Steer;
//!
//! impl TypedUnit for Steer {
//!     const NAME: &'static str = "Steer";
//!     type Inputs = (Stamped<RobotState>, Stamped<Blob>);
//!     type Output = DrivingDirection;
//!
//!     fn compute(
//!         &self,
//!         (robot, blob): Self::Inputs,
//!         qtime: Time,
//!     ) -> Result<Stamped<DrivingDirection>, ComputeError> {
//!         let (dx, dy) = (blob.value.x as f64 - robot.value.x, blob.value.y as f64 - robot.value.y);
//!         let dir = dy.atan2(dx).to_degrees();
//!         Ok(Stamped::new("steer", robot.valid_time, qtime, DrivingDirection { dir, speed: 1.0 }))
//!     }
//! }
//!
//! let esgm = InProcessEsgm::default();
//! esgm.add_comp_unit("Steer", DrivingDirection::TYPE_NAME, Steer::input_types(),
//!     Arc::new(TypedUnitAdapter(Steer))).unwrap();
//! let robot = esgm.create_primitive_entity_trajectory_structure("robot", "RobotState").unwrap();
//! let blob = esgm.create_primitive_entity_trajectory_structure("blob", "Blob").unwrap();
//! let steer =
//!     esgm.create_computed_entity_trajectory_structure("steer", "Steer", &["robot", "blob"]).unwrap();
//! robot.add(RobotState { x: 0.0, y: 0.0, dir: 0.0 }.to_structure("r", secs(1), secs(1))).unwrap();
//! blob.add(Blob { x: 1, y: 0, size: 9 }.to_structure("b", secs(1), secs(1))).unwrap();
//! esgm.flush(Instant::now() + Duration::from_secs(5)).unwrap();
//! let out = DrivingDirection::from_shared(&steer.get_latest().unwrap()).unwrap();
//! assert_eq!(out.dir, 0.0);
//! ```

use crate::entity::{Entity, FromEntityError};
use crate::esgm::{CompUnit, ComputeError, InputType};
use crate::sample::Sample;
use crate::time::Time;
use crate::value::frame::EntityStructure;

/// A value of a unit's input or output with its structure's name and times: what a
/// typed unit receives for each input, and returns.
#[derive(Debug, Clone, PartialEq)]
pub struct Stamped<T> {
    /// The structure's name (an input's, as its producer named it; the output's, as the
    /// unit names it).
    pub name: String,
    /// When the value holds.
    pub valid_time: Time,
    /// When it was made.
    pub create_time: Time,
    /// The value.
    pub value: T,
}

impl<T> Stamped<T> {
    /// `value`, named `name`, valid at `valid_time`, made at `create_time`.
    pub fn new(name: impl Into<String>, valid_time: Time, create_time: Time, value: T) -> Self {
        Self { name: name.into(), valid_time, create_time, value }
    }
}

impl<T: Entity> Stamped<T> {
    /// The structure this value is.
    pub fn to_structure(&self) -> EntityStructure {
        self.value.to_structure(self.name.clone(), self.valid_time, self.create_time)
    }

    /// Input `position` of unit `unit` as a `T`, or why it is not one.
    fn read(unit: &'static str, position: usize, sample: &Sample) -> Result<Self, ComputeError> {
        let value = T::from_shared(&sample.structure).map_err(|source: FromEntityError| {
            ComputeError::Failed {
                reason: format!(
                    "input {position} of {unit} is not a readable `{}`: {source}",
                    T::TYPE_NAME
                ),
            }
        })?;
        Ok(Self::new(sample.name().to_owned(), sample.valid_time(), sample.create_time(), value))
    }
}

/// A tuple of a typed unit's inputs, `(Stamped<A>,)` to `(Stamped<A>, …, Stamped<F>)`:
/// their registered types, in order, and how to read them from samples.
pub trait UnitInputs: Sized {
    /// The input types, in input order, as a runtime registers them.
    fn input_types() -> Vec<InputType>;

    /// The samples read as the tuple; a wrong count or type is a failed call.
    fn read(unit: &'static str, samples: &[Sample]) -> Result<Self, ComputeError>;
}

macro_rules! unit_inputs {
    ($n:literal; $($t:ident $i:tt),+) => {
        impl<$($t: Entity),+> UnitInputs for ($(Stamped<$t>,)+) {
            fn input_types() -> Vec<InputType> {
                vec![$(InputType::Type($t::TYPE_NAME.to_owned())),+]
            }

            fn read(unit: &'static str, samples: &[Sample]) -> Result<Self, ComputeError> {
                if samples.len() != $n {
                    return Err(ComputeError::Failed {
                        reason: format!("{unit} takes {} input(s), got {}", $n, samples.len()),
                    });
                }
                Ok(($(Stamped::<$t>::read(unit, $i, &samples[$i])?,)+))
            }
        }
    };
}

unit_inputs!(1; A 0);
unit_inputs!(2; A 0, B 1);
unit_inputs!(3; A 0, B 1, C 2);
unit_inputs!(4; A 0, B 1, C 2, D 3);
unit_inputs!(5; A 0, B 1, C 2, D 3, E 4);
unit_inputs!(6; A 0, B 1, C 2, D 3, E 4, F 5);

/// A computational unit with declared input and output types (see the module docs).
/// Register it with [`TypedUnitAdapter`] (`esgm.add_comp_unit(name,
/// U::Output::TYPE_NAME, U::input_types(), Arc::new(TypedUnitAdapter(unit)))`), on
/// either runtime.
pub trait TypedUnit: Send + Sync {
    /// The unit's name in errors (usually the name it is registered under).
    const NAME: &'static str;
    /// Its inputs, in input order: a tuple of [`Stamped`] entity types.
    type Inputs: UnitInputs;
    /// The type of what it produces.
    type Output: Entity;

    /// Computes an output from the latest value of each input, asked at `qtime`
    /// ([`CompUnit::compute`]). `Err(ComputeError::ValueNotAvailable)`: no output
    /// this time.
    fn compute(
        &self,
        inputs: Self::Inputs,
        qtime: Time,
    ) -> Result<Stamped<Self::Output>, ComputeError>;

    /// Computes the output valid at `t` from the inputs as their generators give them at
    /// `t` (a temporal function, [`CompUnit::compute_at`]). Optional.
    fn compute_at(
        &self,
        inputs: Self::Inputs,
        t: Time,
    ) -> Result<Stamped<Self::Output>, ComputeError> {
        let _ = (inputs, t);
        Err(ComputeError::OperationNotSupported)
    }

    /// The input types to register, from [`TypedUnit::Inputs`].
    fn input_types() -> Vec<InputType> {
        Self::Inputs::input_types()
    }

    /// [`CompUnit::compute`] of this unit: the samples read as its inputs, its output
    /// as a structure. For a unit that implements [`CompUnit`] itself.
    fn compute_samples(
        &self,
        inputs: &[Sample],
        qtime: Time,
    ) -> Result<EntityStructure, ComputeError> {
        let inputs = Self::Inputs::read(Self::NAME, inputs)?;
        Ok(self.compute(inputs, qtime)?.to_structure())
    }

    /// [`CompUnit::compute_at`] of this unit, as [`TypedUnit::compute_samples`].
    fn compute_samples_at(
        &self,
        inputs: &[Sample],
        t: Time,
    ) -> Result<EntityStructure, ComputeError> {
        let inputs = Self::Inputs::read(Self::NAME, inputs)?;
        Ok(self.compute_at(inputs, t)?.to_structure())
    }
}

/// A [`TypedUnit`] as the [`CompUnit`] runtimes call.
#[derive(Debug, Clone, Copy, Default)]
pub struct TypedUnitAdapter<U>(pub U);

impl<U: TypedUnit> CompUnit for TypedUnitAdapter<U> {
    fn compute(&self, inputs: &[Sample], qtime: Time) -> Result<EntityStructure, ComputeError> {
        self.0.compute_samples(inputs, qtime)
    }

    fn compute_at(&self, inputs: &[Sample], t: Time) -> Result<EntityStructure, ComputeError> {
        self.0.compute_samples_at(inputs, t)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::library::{Blob, RobotState};
    use std::sync::Arc;

    struct Largest;

    impl TypedUnit for Largest {
        const NAME: &'static str = "Largest";
        type Inputs = (Stamped<Blob>, Stamped<Blob>);
        type Output = Blob;

        fn compute(
            &self,
            (a, b): Self::Inputs,
            qtime: Time,
        ) -> Result<Stamped<Blob>, ComputeError> {
            let valid = a.valid_time.max(b.valid_time);
            let value = if a.value.size >= b.value.size { a.value } else { b.value };
            Ok(Stamped::new("largest", valid, qtime, value))
        }
    }

    fn sample<T: Entity>(value: &T, vt: Time) -> Sample {
        Sample::new(Arc::new(value.to_structure("in", vt, vt)), vt, vt)
    }

    #[test]
    fn inputs_are_read_by_type_and_the_output_is_stamped() {
        let unit = TypedUnitAdapter(Largest);
        let a = Blob { x: 1, y: 1, size: 3 };
        let b = Blob { x: 2, y: 2, size: 7 };
        let out = unit.compute(&[sample(&a, 10), sample(&b, 20)], 30).unwrap();
        assert_eq!((out.name.as_str(), out.valid_time, out.create_time), ("largest", 20, 30));
        assert_eq!(Blob::from_structure(&out).unwrap(), b);
        assert_eq!(
            Largest::input_types(),
            vec![InputType::Type("Blob".into()), InputType::Type("Blob".into())]
        );
    }

    #[test]
    fn a_wrong_count_or_type_fails_the_call_naming_the_input() {
        let unit = TypedUnitAdapter(Largest);
        let blob = sample(&Blob { x: 1, y: 1, size: 3 }, 10);
        let robot = sample(&RobotState { x: 0.0, y: 0.0, dir: 0.0 }, 10);
        let ComputeError::Failed { reason } =
            unit.compute(std::slice::from_ref(&blob), 30).unwrap_err()
        else {
            panic!("a failed call");
        };
        assert!(reason.contains("takes 2 input(s), got 1"), "{reason}");
        let ComputeError::Failed { reason } = unit.compute(&[blob, robot], 30).unwrap_err() else {
            panic!("a failed call");
        };
        assert!(reason.contains("input 1 of Largest") && reason.contains("`Blob`"), "{reason}");
        assert_eq!(
            unit.compute_at(&[], 1).unwrap_err(),
            ComputeError::Failed { reason: "Largest takes 2 input(s), got 0".into() }
        );
    }
}
