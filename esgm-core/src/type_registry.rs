//! The registry of entity structure types (E1): `create_entity_structure_type`,
//! `destroy_entity_structure_type`, `get_entity_structure_type`.
//!
//! Types are stored behind `Arc` so that a trajectory keeps the definition it was
//! created with: destroying or re-registering a type never changes what an existing
//! trajectory accepts.

use std::collections::HashMap;
use std::sync::Arc;

use crate::types::{EntityStructureType, TypeDefinitionError};

/// Errors of the type-registry operations, named as the seed's exceptions.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum TypeRegistryError {
    /// A type is already registered under that name; destroy it first or pick another.
    #[error("entity structure type `{name}` already exists")]
    EntityStructureTypeAlreadyExists {
        /// The name.
        name: String,
    },
    /// No type is registered under that name; register it first (check the spelling).
    #[error("no entity structure type `{name}`{}", did_you_mean(suggestion))]
    NoSuchEntityStructureType {
        /// The unknown name.
        name: String,
        /// The closest registered name, if one is close.
        suggestion: Option<String>,
    },
    /// The definition is not self-consistent.
    #[error(transparent)]
    InvalidDefinition(#[from] TypeDefinitionError),
    /// The ESGM could not be reached or did not answer (a remote runtime whose
    /// coordinator is gone, stuck or unreachable — CORBA's `COMM_FAILURE`). Nothing
    /// was changed by this call as far as the caller can tell; retry or check the
    /// coordinator.
    #[error("the ESGM is unavailable: {reason}")]
    Unavailable {
        /// Why.
        reason: crate::failures::Unreachable,
    },
}

pub(crate) fn did_you_mean(s: &Option<String>) -> String {
    s.as_ref().map(|s| format!("; did you mean `{s}`?")).unwrap_or_default()
}

/// Registered entity structure types, keyed by the name they were registered under.
#[derive(Debug, Default, Clone)]
pub struct TypeRegistry {
    types: HashMap<String, Arc<EntityStructureType>>,
}

impl TypeRegistry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }

    /// A registry holding the predefined library types (see [`crate::library`]).
    pub fn with_library() -> Self {
        let mut r = Self::new();
        for t in crate::library::predefined_types() {
            // The library's names are distinct and its definitions valid (tested there).
            let _ = r.create_entity_structure_type(t.name.clone(), t);
        }
        r
    }

    /// Registers `entity_type` under `type_name`.
    pub fn create_entity_structure_type(
        &mut self,
        type_name: impl Into<String>,
        entity_type: EntityStructureType,
    ) -> Result<(), TypeRegistryError> {
        let type_name = type_name.into();
        entity_type.validate()?;
        if self.types.contains_key(&type_name) {
            return Err(TypeRegistryError::EntityStructureTypeAlreadyExists { name: type_name });
        }
        self.types.insert(type_name, Arc::new(entity_type));
        Ok(())
    }

    /// Removes the type registered under `type_name`. Trajectories already created with
    /// it keep their copy.
    pub fn destroy_entity_structure_type(
        &mut self,
        type_name: &str,
    ) -> Result<Arc<EntityStructureType>, TypeRegistryError> {
        self.types.remove(type_name).ok_or_else(|| self.no_such(type_name))
    }

    /// The type registered under `type_name`.
    pub fn get_entity_structure_type(
        &self,
        type_name: &str,
    ) -> Result<Arc<EntityStructureType>, TypeRegistryError> {
        self.types.get(type_name).cloned().ok_or_else(|| self.no_such(type_name))
    }

    /// Registered names, sorted.
    pub fn names(&self) -> Vec<String> {
        let mut v: Vec<_> = self.types.keys().cloned().collect();
        v.sort();
        v
    }

    /// Number of registered types.
    pub fn len(&self) -> usize {
        self.types.len()
    }

    /// True if no type is registered.
    pub fn is_empty(&self) -> bool {
        self.types.is_empty()
    }

    pub(crate) fn no_such(&self, name: &str) -> TypeRegistryError {
        TypeRegistryError::NoSuchEntityStructureType {
            name: name.to_owned(),
            suggestion: closest_name(name, self.types.keys().map(String::as_str)),
        }
    }
}

/// The candidate closest to `name` by edit distance, if it is close enough to be a
/// plausible typo (at most a third of the name's length, and at least one edit).
pub fn closest_name<'a>(name: &str, candidates: impl Iterator<Item = &'a str>) -> Option<String> {
    let limit = (name.chars().count() / 3).max(1);
    candidates
        .map(|c| (edit_distance(name, c), c))
        .filter(|(d, _)| *d <= limit)
        .min()
        .map(|(_, c)| c.to_owned())
}

/// Optimal-string-alignment distance: insertions, deletions, substitutions and swaps
/// of two adjacent characters each cost one (so `szie` is one edit from `size`, the
/// commonest typo).
fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    // d[i][j]: distance between a[..i] and b[..j].
    let mut d = vec![vec![0usize; b.len() + 1]; a.len() + 1];
    for (i, row) in d.iter_mut().enumerate() {
        row[0] = i;
    }
    for (j, cell) in d[0].iter_mut().enumerate() {
        *cell = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut v = (d[i - 1][j] + 1).min(d[i][j - 1] + 1).min(d[i - 1][j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                v = v.min(d[i - 2][j - 2] + 1);
            }
            d[i][j] = v;
        }
    }
    d[a.len()][b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::value::ValueSort;

    #[test]
    fn create_get_destroy_with_seed_errors() {
        let mut r = TypeRegistry::new();
        let blob = EntityStructureType::new("BlobType").attr("x", ValueSort::Long);
        r.create_entity_structure_type("blob", blob.clone()).unwrap();
        assert_eq!(*r.get_entity_structure_type("blob").unwrap(), blob);
        assert_eq!(
            r.create_entity_structure_type("blob", blob.clone()),
            Err(TypeRegistryError::EntityStructureTypeAlreadyExists { name: "blob".into() })
        );
        let err = r.get_entity_structure_type("blb").unwrap_err();
        assert_eq!(err.to_string(), "no entity structure type `blb`; did you mean `blob`?");
        r.destroy_entity_structure_type("blob").unwrap();
        assert!(matches!(
            r.destroy_entity_structure_type("blob"),
            Err(TypeRegistryError::NoSuchEntityStructureType { .. })
        ));
        // A destroyed name can be registered again.
        r.create_entity_structure_type("blob", blob).unwrap();
    }

    #[test]
    fn invalid_definitions_are_refused() {
        let mut r = TypeRegistry::new();
        let bad =
            EntityStructureType::new("T").attr("x", ValueSort::Long).attr("x", ValueSort::Bool);
        assert!(matches!(
            r.create_entity_structure_type("T", bad),
            Err(TypeRegistryError::InvalidDefinition(_))
        ));
        assert!(r.is_empty());
    }

    #[test]
    fn suggestions_only_for_close_names() {
        let names = ["blobs", "images", "robot_state"];
        assert_eq!(closest_name("blobz", names.into_iter()), Some("blobs".into()));
        assert_eq!(closest_name("zzz", names.into_iter()), None);
        assert_eq!(closest_name("szie", ["size", "x"].into_iter()), Some("size".into()));
    }
}
