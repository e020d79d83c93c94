//! esgm's errors as Python exceptions named as the seed's IDL names them
//! (`NoSuchEntityStructure`, `PolicyViolation`, `ValueNotAvailable`, …), all subclasses
//! of `esgm.EsgmError`, with the same messages as in Rust.
//!
//! One implementation for every error enum: each is serialisable (it crosses processes),
//! and its serialised form names the variant; the variant's name picks the exception.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(esgm, EsgmError, PyException, "Every esgm error.");
create_exception!(esgm, NoSuchEntityStructure, EsgmError, "No trajectory of this name.");
create_exception!(esgm, NoSuchEntityStructureType, EsgmError, "No type of this name.");
create_exception!(esgm, EntityStructureAlreadyExists, EsgmError, "The name is taken.");
create_exception!(esgm, EntityStructureTypeAlreadyExists, EsgmError, "The type name is taken.");
create_exception!(esgm, NoSuchSensor, EsgmError, "No sensor of this name.");
create_exception!(esgm, NoSuchCompUnit, EsgmError, "No computational unit of this name.");
create_exception!(esgm, SensorAlreadyExists, EsgmError, "The sensor name is taken.");
create_exception!(esgm, CompUnitAlreadyExists, EsgmError, "The unit name is taken.");
create_exception!(esgm, ValueNotAvailable, EsgmError, "No sample answers the query.");
create_exception!(esgm, PolicyViolation, EsgmError, "The trajectory's policy refused it.");
create_exception!(esgm, InvalidType, EsgmError, "The structure does not fit the type.");
create_exception!(esgm, OperationNotSupported, EsgmError, "Not on this trajectory.");
create_exception!(esgm, IllegalPolicy, EsgmError, "The policy cannot be.");
create_exception!(esgm, LimitReached, EsgmError, "A limit of the domain was reached.");
create_exception!(esgm, WriterGone, EsgmError, "The trajectory's writer has exited.");
create_exception!(esgm, Unavailable, EsgmError, "A part of the system did not answer.");

/// Every exception class, for the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("EsgmError", py.get_type::<EsgmError>())?;
    m.add("NoSuchEntityStructure", py.get_type::<NoSuchEntityStructure>())?;
    m.add("NoSuchEntityStructureType", py.get_type::<NoSuchEntityStructureType>())?;
    m.add("EntityStructureAlreadyExists", py.get_type::<EntityStructureAlreadyExists>())?;
    m.add("EntityStructureTypeAlreadyExists", py.get_type::<EntityStructureTypeAlreadyExists>())?;
    m.add("NoSuchSensor", py.get_type::<NoSuchSensor>())?;
    m.add("NoSuchCompUnit", py.get_type::<NoSuchCompUnit>())?;
    m.add("SensorAlreadyExists", py.get_type::<SensorAlreadyExists>())?;
    m.add("CompUnitAlreadyExists", py.get_type::<CompUnitAlreadyExists>())?;
    m.add("ValueNotAvailable", py.get_type::<ValueNotAvailable>())?;
    m.add("PolicyViolation", py.get_type::<PolicyViolation>())?;
    m.add("InvalidType", py.get_type::<InvalidType>())?;
    m.add("OperationNotSupported", py.get_type::<OperationNotSupported>())?;
    m.add("IllegalPolicy", py.get_type::<IllegalPolicy>())?;
    m.add("LimitReached", py.get_type::<LimitReached>())?;
    m.add("WriterGone", py.get_type::<WriterGone>())?;
    m.add("Unavailable", py.get_type::<Unavailable>())?;
    Ok(())
}

/// The variant name of a serialisable error enum (`"NoSuchEntityStructure"`).
fn variant<E: serde::Serialize>(e: &E) -> Option<String> {
    match serde_json::to_value(e).ok()? {
        serde_json::Value::String(s) => Some(s),
        serde_json::Value::Object(m) => m.keys().next().cloned(),
        _ => None,
    }
}

/// `e` as the Python exception of its variant, with its message.
pub fn to_py<E: serde::Serialize + std::fmt::Display>(e: &E) -> PyErr {
    let message = e.to_string();
    match variant(e).as_deref() {
        Some("NoSuchEntityStructure") => NoSuchEntityStructure::new_err(message),
        Some("NoSuchEntityStructureType") => NoSuchEntityStructureType::new_err(message),
        Some("EntityStructureAlreadyExists") => EntityStructureAlreadyExists::new_err(message),
        Some("EntityStructureTypeAlreadyExists") => {
            EntityStructureTypeAlreadyExists::new_err(message)
        }
        Some("NoSuchSensor") => NoSuchSensor::new_err(message),
        Some("NoSuchCompUnit") => NoSuchCompUnit::new_err(message),
        Some("SensorAlreadyExists") => SensorAlreadyExists::new_err(message),
        Some("CompUnitAlreadyExists") => CompUnitAlreadyExists::new_err(message),
        Some("ValueNotAvailable") => ValueNotAvailable::new_err(message),
        Some("PolicyViolation") => PolicyViolation::new_err(message),
        // A structure, an input or a definition that does not fit its type.
        Some(
            "InvalidType"
            | "InvalidInput"
            | "WrongInputCount"
            | "InvalidTypeDefinition"
            | "InvalidDefinition"
            | "TypeChange",
        ) => InvalidType::new_err(message),
        Some("OperationNotSupported") => OperationNotSupported::new_err(message),
        Some("IllegalPolicy") => IllegalPolicy::new_err(message),
        Some("LimitReached") => LimitReached::new_err(message),
        Some("WriterGone") => WriterGone::new_err(message),
        Some("Unavailable" | "Incomplete") => Unavailable::new_err(message),
        _ => EsgmError::new_err(message),
    }
}
