//! What the coordinator accepts from a client: bounded requests and well-formed names.
//!
//! Any local process can ask the coordinator, so nothing a request carries may make it
//! spend unbounded time or memory. Two bounds do it:
//! - a request's size ([`MAX_REQUEST_BYTES`]), checked before it is decoded;
//! - every name's length ([`MAX_NAME_LEN`]), checked before it is looked up. Names in
//!   the registry are bounded the same way, so the "did you mean" search (an edit
//!   distance against each known name) costs at most `MAX_NAME_LEN²` per candidate.

use esgm_core::esgm::{TrajectorySource, TrajectorySpec};

use super::protocol::{ControlError, Request};

/// The longest name (type, trajectory, sensor, unit, process, host) the coordinator
/// accepts, in bytes. A trajectory's name becomes part of iceoryx2 service names
/// (at most 255 bytes with the domain and kind), so longer ones could not be served.
pub const MAX_NAME_LEN: usize = 100;

/// The largest request the coordinator decodes, in bytes. Requests carry names, types
/// and policies (a few hundred bytes to a few KiB); a type with thousands of
/// attributes still fits.
pub const MAX_REQUEST_BYTES: usize = 256 * 1024;

/// The rule of names a name breaks ([`ControlError::IllegalName`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum NameRule {
    /// A name has at least one character.
    #[error("it is empty")]
    Empty,
    /// A name is at most [`MAX_NAME_LEN`] bytes long.
    #[error("it is {len} bytes long; at most {max} are allowed")]
    TooLong {
        /// Its length in bytes.
        len: usize,
        /// The most allowed.
        max: usize,
    },
    /// A name has no `/` (it becomes part of service and file names), no whitespace
    /// and no control character.
    #[error("it contains {0:?}; `/`, spaces and control characters are not allowed")]
    BadCharacter(char),
}

/// Why a name is refused (see [`ControlError::IllegalName`]); `None` if it is fine.
pub fn name_problem(name: &str) -> Option<NameRule> {
    if name.is_empty() {
        return Some(NameRule::Empty);
    }
    if name.len() > MAX_NAME_LEN {
        return Some(NameRule::TooLong { len: name.len(), max: MAX_NAME_LEN });
    }
    name.chars()
        .find(|c| *c == '/' || c.is_control() || c.is_whitespace())
        .map(NameRule::BadCharacter)
}

/// Checks one name; `what` says what it names (`"trajectory"`, `"type"`…).
pub fn check_name(what: &'static str, name: &str) -> Result<(), ControlError> {
    match name_problem(name) {
        None => Ok(()),
        Some(reason) => {
            Err(ControlError::IllegalName { what: what.to_owned(), name: shown(name), reason })
        }
    }
}

/// A name as an error message shows it: at most 64 characters, so that an error about
/// a 4 MiB name is not 4 MiB long.
fn shown(name: &str) -> String {
    const SHOWN: usize = 64;
    if name.chars().count() <= SHOWN {
        return name.to_owned();
    }
    let head: String = name.chars().take(SHOWN).collect();
    format!("{head}… ({} bytes)", name.len())
}

fn check_spec(spec: &TrajectorySpec) -> Result<(), ControlError> {
    check_name("trajectory", &spec.name)?;
    for input in spec.inputs() {
        check_name("input trajectory", &input)?;
    }
    match &spec.source {
        TrajectorySource::Primitive { type_name } => check_name("type", type_name),
        TrajectorySource::Sampled { sensor, .. } => check_name("sensor", sensor),
        TrajectorySource::Computed { unit, .. } => check_name("unit", unit),
        TrajectorySource::SampledGenerators { unit: Some(unit), .. } => check_name("unit", unit),
        _ => Ok(()),
    }
}

/// Checks every name `request` carries before the registry looks any of them up.
pub fn check_request(request: &Request) -> Result<(), ControlError> {
    match request {
        Request::CreateEntityStructureType { type_name, .. }
        | Request::DestroyEntityStructureType { type_name }
        | Request::GetEntityStructureType { type_name }
        | Request::GetTypeDefinitions { type_name } => check_name("type", type_name),
        Request::AddSensorInterface { sensor, type_name, host } => {
            check_name("sensor", sensor)?;
            check_name("type", type_name)?;
            check_name("host", host)
        }
        Request::RemoveSensorInterface { sensor } => check_name("sensor", sensor),
        Request::AddCompUnit { name, type_name, input_types, host } => {
            check_name("unit", name)?;
            check_name("type", type_name)?;
            for input in input_types {
                if let esgm_core::esgm::InputType::Type(t) = input {
                    check_name("input type", t)?;
                }
            }
            check_name("host", host)
        }
        Request::RemoveCompUnit { name } => check_name("unit", name),
        Request::CreateTrajectory { spec, host } => {
            check_spec(spec)?;
            check_name("host", host)
        }
        Request::GetEntityTrajectoryStructure { name }
        | Request::DestroyEntityTrajectoryStructure { name }
        | Request::ReportWriter { trajectory: name, .. }
        | Request::ReleaseWriter { trajectory: name, .. } => check_name("trajectory", name),
        Request::TakeOverTrajectory { trajectory, host, .. } => {
            check_name("trajectory", trajectory)?;
            check_name("host", host)
        }
        Request::ReportHoldings { host, .. } | Request::Assignments { host } => {
            check_name("host", host)
        }
        Request::DeclareProcess { spec } => check_name("process", &spec.name),
        Request::ListPlacementsOf { names } => {
            names.iter().try_for_each(|n| check_name("trajectory", n))
        }
        Request::RemoveProcess { name } | Request::ReportProcess { name, .. } => {
            check_name("process", name)
        }
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]

    use super::*;

    #[test]
    fn empty_slashed_long_and_control_names_are_refused() {
        for bad in ["", "a/b", "a b", "tab\there", &"x".repeat(MAX_NAME_LEN + 1)] {
            match check_name("trajectory", bad) {
                Err(ControlError::IllegalName { what, .. }) if what == "trajectory" => {}
                other => panic!("{bad:?}: {other:?}"),
            }
        }
        for good in ["robot_state", "camera-1", "a.b:c", &"x".repeat(MAX_NAME_LEN)] {
            check_name("trajectory", good).unwrap();
        }
    }

    #[test]
    fn an_error_about_a_huge_name_is_short() {
        let huge = "y".repeat(4 << 20);
        let e = check_name("type", &huge).unwrap_err().to_string();
        assert!(e.len() < 300, "{} bytes", e.len());
        assert!(e.contains("4194304 bytes"), "{e}");
    }
}
