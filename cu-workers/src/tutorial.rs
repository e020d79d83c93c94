//! The tutorial's units registered in one call (chapter 9's three `add_comp_unit`s).

use std::sync::Arc;

use esgm_core::esgm::TypedUnitAdapter;
use esgm_core::{Esgm, RegistrationError};

use crate::{BlobDetectionUnit, BlobSelectionUnit, DrivingDirectionUnit};

/// Registers `BlobDetection`, `BlobSelection` and `DrivingDirection` with their default
/// settings (a 640-pixel-wide, 60° camera) and typed inputs, on any runtime.
///
/// Stops at the first refusal, leaving the units before it registered: a name already
/// taken ([`RegistrationError::CompUnitAlreadyExists`]) or a library type missing from
/// the runtime's registry ([`RegistrationError::NoSuchEntityStructureType`]). To use
/// other settings, register the units yourself the same way.
pub fn register_tutorial_units(esgm: &impl Esgm) -> Result<(), RegistrationError> {
    esgm.add_comp_unit(
        BlobDetectionUnit::NAME,
        BlobDetectionUnit::OUTPUT_TYPE,
        BlobDetectionUnit::input_types(),
        Arc::new(TypedUnitAdapter(BlobDetectionUnit::default())),
    )?;
    esgm.add_comp_unit(
        BlobSelectionUnit::NAME,
        BlobSelectionUnit::OUTPUT_TYPE,
        BlobSelectionUnit::input_types(),
        Arc::new(TypedUnitAdapter(BlobSelectionUnit)),
    )?;
    esgm.add_comp_unit(
        DrivingDirectionUnit::NAME,
        DrivingDirectionUnit::OUTPUT_TYPE,
        DrivingDirectionUnit::input_types(),
        Arc::new(TypedUnitAdapter(DrivingDirectionUnit::default())),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::{InProcessEsgm, InputType};

    #[test]
    fn registers_the_three_units_with_typed_inputs() {
        let esgm = InProcessEsgm::default();
        register_tutorial_units(&esgm).unwrap();
        let ty = |t: &str| InputType::Type(t.to_owned());
        let mut units = esgm.comp_units().unwrap();
        units.sort_by(|a, b| a.0.cmp(&b.0));
        assert_eq!(
            units,
            vec![
                ("BlobDetection".into(), "BlobSeq".into(), vec![ty("Image")]),
                ("BlobSelection".into(), "Blob".into(), vec![ty("BlobSeq")]),
                (
                    "DrivingDirection".into(),
                    "DrivingDirection".into(),
                    vec![ty("RobotState"), ty("Blob")]
                ),
            ]
        );
        assert_eq!(
            register_tutorial_units(&esgm),
            Err(RegistrationError::CompUnitAlreadyExists { name: "BlobDetection".into() })
        );
    }
}
