//! A type arriving from another host: registered here, or refused naming the attribute
//! where a type of the same name differs.

use esgm_core::esgm::Esgm;
use esgm_core::{Attr, EntityStructureType, TypeRegistryError};

/// A remote type differs from the local type of the same name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("type `{type_name}` differs between `{remote}` and this domain: {difference}")]
pub struct TypeConflict {
    /// The type.
    pub type_name: String,
    /// Where the other definition comes from (`<domain>/<trajectory>`).
    pub remote: String,
    /// The first difference, naming its attribute.
    pub difference: String,
}

/// Registering a remote type failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ImportTypeError {
    /// A local type of the same name differs; rename one of them.
    #[error(transparent)]
    Conflict(#[from] TypeConflict),
    /// The local system refused the registration (see the reason).
    #[error("cannot register type `{type_name}` here: {source}")]
    Register {
        /// The type.
        type_name: String,
        /// Why.
        source: TypeRegistryError,
    },
}

fn describe(a: &Attr) -> String {
    match &a.element_type {
        Some(e) => format!("{} of {e}", a.sort),
        None => a.sort.to_string(),
    }
}

/// The first difference between two definitions of a type, naming its attribute;
/// `None` when they are the same.
pub fn difference(remote: &EntityStructureType, local: &EntityStructureType) -> Option<String> {
    for r in &remote.attributes {
        match local.attributes.iter().find(|l| l.name == r.name) {
            None => {
                return Some(format!("attribute `{}` ({}) is missing here", r.name, describe(r)));
            }
            Some(l) if l != r => {
                return Some(format!(
                    "attribute `{}` is {} there, {} here",
                    r.name,
                    describe(r),
                    describe(l)
                ));
            }
            Some(_) => {}
        }
    }
    if let Some(l) = local.attributes.iter().find(|l| remote.attribute(&l.name).is_none()) {
        return Some(format!("attribute `{}` ({}) is missing there", l.name, describe(l)));
    }
    let order = |t: &EntityStructureType| t.attributes.iter().map(|a| a.name.clone()).collect();
    let (ro, lo): (Vec<String>, Vec<String>) = (order(remote), order(local));
    (ro != lo).then(|| format!("attributes are in another order ({} there)", ro.join(", ")))
}

/// Registers every definition (the trajectory's type `main` and the element types it
/// names) that `esgm` does not know yet; a known one must be identical.
pub fn register<E: Esgm>(
    esgm: &E,
    remote: &str,
    main: &str,
    definitions: &[(String, EntityStructureType)],
) -> Result<(), ImportTypeError> {
    // Check all first: nothing is registered when any conflicts.
    let mut missing = Vec::new();
    for (name, def) in definitions {
        match esgm.get_entity_structure_type(name) {
            Ok(local) => {
                if let Some(difference) = difference(def, &local) {
                    return Err(TypeConflict {
                        type_name: name.clone(),
                        remote: remote.to_owned(),
                        difference,
                    }
                    .into());
                }
            }
            // Not here (or unreadable): creating it below reports any real failure.
            Err(_) => missing.push((name, def)),
        }
    }
    // Element types first, so a type that names one finds it.
    missing.sort_by_key(|(name, _)| name.as_str() == main);
    for (name, def) in missing {
        esgm.create_entity_structure_type(name, def.clone())
            .map_err(|source| ImportTypeError::Register { type_name: name.clone(), source })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::value::ValueSort;

    #[test]
    fn the_difference_names_the_attribute() {
        let remote = EntityStructureType::new("RobotState")
            .attr("x", ValueSort::Double)
            .attr("y", ValueSort::Double);
        let same = remote.clone();
        assert_eq!(difference(&remote, &same), None);
        let other = EntityStructureType::new("RobotState")
            .attr("x", ValueSort::Long)
            .attr("y", ValueSort::Double);
        let d = difference(&remote, &other).unwrap_or_default();
        assert!(d.contains("`x`") && d.contains("there"), "{d}");
        let fewer = EntityStructureType::new("RobotState").attr("x", ValueSort::Double);
        assert!(difference(&remote, &fewer).unwrap_or_default().contains("`y`"));
        let more = remote.clone().attr("z", ValueSort::Bool);
        assert!(difference(&remote, &more).unwrap_or_default().contains("`z`"));
    }
}
