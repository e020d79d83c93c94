//! Checking entity structures against their type (M4), recursively through nested
//! frames and frame sequences.
//!
//! A [`TypeChecker`] is built once, when a trajectory is created: it resolves the
//! trajectory's type and every element type reachable from it into a snapshot, so that
//! checking a structure never takes the registry lock, and later changes to the
//! registry never change what an existing trajectory accepts.

use std::collections::HashMap;
use std::sync::Arc;

use crate::structure::{Attributes, SharedStructure};
use crate::type_registry::{TypeRegistry, TypeRegistryError};
use crate::types::EntityStructureType;
use crate::value::ValueSort;
use crate::value::frame::AttributeValuePair;

/// A structure does not fit its type (the seed's `InvalidType`, with the attribute
/// named). Attribute paths name nested positions, e.g. `items[2].size`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum InvalidType {
    /// The type declares an attribute the structure does not assign.
    #[error("attribute `{attribute}` of type `{type_name}` is missing (expected {expected})")]
    MissingAttribute {
        /// The type being checked.
        type_name: String,
        /// Path of the missing attribute.
        attribute: String,
        /// Its declared sort.
        expected: ValueSort,
    },
    /// The attribute's value has the wrong sort (the seed's `desired_type`/`actual_type`).
    #[error("attribute `{attribute}` of type `{type_name}` is {actual}, expected {expected}")]
    WrongSort {
        /// The type being checked.
        type_name: String,
        /// Path of the attribute.
        attribute: String,
        /// The declared sort (`desired_type`).
        expected: ValueSort,
        /// The sort found (`actual_type`).
        actual: ValueSort,
    },
    /// The structure assigns an attribute its type does not declare (often a typo).
    #[error("attribute `{attribute}` is not declared by type `{type_name}`")]
    UnknownAttribute {
        /// The type being checked.
        type_name: String,
        /// Path of the undeclared attribute.
        attribute: String,
    },
    /// The structure assigns one attribute twice.
    #[error("attribute `{attribute}` of type `{type_name}` is assigned twice")]
    DuplicateAttribute {
        /// The type being checked.
        type_name: String,
        /// Path of the attribute.
        attribute: String,
    },
}

/// Checks attribute lists against one entity structure type and, recursively, the
/// element types its frame attributes name.
#[derive(Debug, Clone)]
pub struct TypeChecker {
    root: String,
    types: Arc<HashMap<String, Arc<EntityStructureType>>>,
}

impl TypeChecker {
    /// Resolves `type_name` and every element type reachable from it in `registry`.
    pub fn new(registry: &TypeRegistry, type_name: &str) -> Result<Self, TypeRegistryError> {
        let mut types = HashMap::new();
        let mut pending = vec![type_name.to_owned()];
        while let Some(name) = pending.pop() {
            if types.contains_key(&name) {
                continue;
            }
            let t = registry.get_entity_structure_type(&name)?;
            pending.extend(t.attributes.iter().filter_map(|a| a.element_type.clone()));
            types.insert(name, t);
        }
        Ok(Self { root: type_name.to_owned(), types: Arc::new(types) })
    }

    /// The checked type and every type reachable from it, by registered name: what
    /// another process needs to check the same structures
    /// ([`TypeChecker::from_definitions`]).
    pub fn definitions(&self) -> Vec<(String, EntityStructureType)> {
        let mut v: Vec<_> =
            self.types.iter().map(|(n, t)| (n.clone(), t.as_ref().clone())).collect();
        v.sort_by(|a, b| a.0.cmp(&b.0));
        v
    }

    /// A checker for `root` from definitions received from another process.
    pub fn from_definitions(
        root: &str,
        definitions: impl IntoIterator<Item = (String, EntityStructureType)>,
    ) -> Result<Self, TypeRegistryError> {
        let mut registry = TypeRegistry::new();
        for (name, ty) in definitions {
            registry.create_entity_structure_type(name, ty)?;
        }
        Self::new(&registry, root)
    }

    /// The registered name of the checked type.
    pub fn type_name(&self) -> &str {
        &self.root
    }

    /// The checked type's definition.
    pub fn entity_type(&self) -> &Arc<EntityStructureType> {
        // Present by construction: `new` inserted the root first.
        &self.types[&self.root]
    }

    /// The definition of a type reachable from the root (the root or an element type).
    pub fn resolve(&self, type_name: &str) -> Option<&Arc<EntityStructureType>> {
        self.types.get(type_name)
    }

    /// Checks a structure's (or frame's) attributes against the root type.
    pub fn check(&self, attributes: &[AttributeValuePair]) -> Result<(), InvalidType> {
        self.check_attributes(Attributes::owned(attributes))
    }

    /// Checks a structure against the root type, read in place: an archived one (from
    /// another process) is checked without decoding it.
    pub fn check_structure(&self, structure: &SharedStructure) -> Result<(), InvalidType> {
        self.check_attributes(structure.attributes())
    }

    /// Checks attribute/value pairs read in place against the root type: the one
    /// implementation behind [`Self::check`] and [`Self::check_structure`].
    pub fn check_attributes(&self, attributes: Attributes<'_>) -> Result<(), InvalidType> {
        let mut path = String::new();
        self.check_as(&self.root, attributes, &mut path)
    }

    fn check_as(
        &self,
        type_name: &str,
        attributes: Attributes<'_>,
        path: &mut String,
    ) -> Result<(), InvalidType> {
        let ty = &self.types[type_name];
        let base = path.len();
        let at = |path: &mut String, name: &str| {
            path.truncate(base);
            if base > 0 {
                path.push('.');
            }
            path.push_str(name);
            path.clone()
        };
        // A structure's attributes, in the order the type declares them: matched in one
        // pass when the structure lists them in that order (what every writer esgm
        // makes does), by search otherwise.
        for (i, (name, _)) in attributes.clone().enumerate() {
            if attributes.clone().take(i).any(|(n, _)| n == name) {
                return Err(InvalidType::DuplicateAttribute {
                    type_name: ty.name.clone(),
                    attribute: at(path, name),
                });
            }
            let declared = ty.attributes.get(i).is_some_and(|a| a.name == name);
            if !declared && ty.attribute(name).is_none() {
                return Err(InvalidType::UnknownAttribute {
                    type_name: ty.name.clone(),
                    attribute: at(path, name),
                });
            }
        }
        for (k, attr) in ty.attributes.iter().enumerate() {
            let in_order = attributes.clone().nth(k).filter(|(n, _)| *n == attr.name);
            let Some((_, value)) =
                in_order.or_else(|| attributes.clone().find(|(n, _)| *n == attr.name))
            else {
                return Err(InvalidType::MissingAttribute {
                    type_name: ty.name.clone(),
                    attribute: at(path, &attr.name),
                    expected: attr.sort,
                });
            };
            let actual = value.sort();
            if attr.sort != ValueSort::AnyValue && actual != attr.sort {
                return Err(InvalidType::WrongSort {
                    type_name: ty.name.clone(),
                    attribute: at(path, &attr.name),
                    expected: attr.sort,
                    actual,
                });
            }
            let Some(element) = attr.element_type.as_deref() else { continue };
            if let Some(frame) = value.as_frame() {
                at(path, &attr.name);
                self.check_as(element, frame.attributes(), path)?;
            } else if let Some(frames) = value.as_frames() {
                for k in 0..frames.len() {
                    let Some(frame) = frames.get(k) else { break };
                    at(path, &attr.name);
                    path.push_str(&format!("[{k}]"));
                    self.check_as(element, frame.attributes(), path)?;
                }
            }
        }
        path.truncate(base);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::value::Value;
    use crate::value::frame::{EntityFrame, EntityStructure};

    fn registry() -> TypeRegistry {
        let mut r = TypeRegistry::new();
        r.create_entity_structure_type(
            "Blob",
            EntityStructureType::new("Blob")
                .attr("x", ValueSort::Long)
                .attr("y", ValueSort::Long)
                .attr("size", ValueSort::Long),
        )
        .unwrap();
        r.create_entity_structure_type(
            "BlobSeq",
            EntityStructureType::new("BlobSeq").frame_seq("items", "Blob"),
        )
        .unwrap();
        r.create_entity_structure_type(
            "Tracked",
            EntityStructureType::new("Tracked")
                .frame("best", "Blob")
                .attr("any", ValueSort::AnyValue),
        )
        .unwrap();
        r
    }

    fn blob(x: i64) -> EntityFrame {
        EntityFrame::new("b").with("x", x).with("y", 2i64).with("size", 3i64)
    }

    #[test]
    fn accepts_well_typed_nested_structures() {
        let c = TypeChecker::new(&registry(), "BlobSeq").unwrap();
        let es = EntityStructure::new("blobs", 0, 0).with("items", vec![blob(1), blob(2)]);
        assert_eq!(c.check(&es.attributes), Ok(()));
        let empty = EntityStructure::new("blobs", 0, 0).with("items", Vec::<EntityFrame>::new());
        assert_eq!(c.check(&empty.attributes), Ok(()));
    }

    #[test]
    fn names_the_nested_attribute_that_is_wrong() {
        let c = TypeChecker::new(&registry(), "BlobSeq").unwrap();
        let mut bad = blob(3);
        bad.set("size", 1.5);
        let es = EntityStructure::new("blobs", 0, 0).with("items", vec![blob(1), blob(2), bad]);
        assert_eq!(
            c.check(&es.attributes),
            Err(InvalidType::WrongSort {
                type_name: "Blob".into(),
                attribute: "items[2].size".into(),
                expected: ValueSort::Long,
                actual: ValueSort::Double,
            })
        );
        let missing = EntityFrame::new("b").with("x", 1i64).with("y", 1i64);
        let es = EntityStructure::new("blobs", 0, 0).with("items", vec![missing]);
        let err = c.check(&es.attributes).unwrap_err();
        assert_eq!(
            err.to_string(),
            "attribute `items[0].size` of type `Blob` is missing (expected Long)"
        );
    }

    #[test]
    fn rejects_unknown_duplicate_and_no_value() {
        let c = TypeChecker::new(&registry(), "Blob").unwrap();
        let typo = blob(1).with("szie", 3i64);
        assert!(matches!(c.check(&typo.attributes), Err(InvalidType::UnknownAttribute { .. })));
        let mut dup = blob(1);
        dup.attributes.push(AttributeValuePair::new("x", 5i64));
        assert!(matches!(c.check(&dup.attributes), Err(InvalidType::DuplicateAttribute { .. })));
        let none = blob(1).with("x", Value::NoValue);
        assert!(matches!(
            c.check(&none.attributes),
            Err(InvalidType::WrongSort { actual: ValueSort::NoValue, .. })
        ));
    }

    #[test]
    fn frame_attribute_and_any_value() {
        let c = TypeChecker::new(&registry(), "Tracked").unwrap();
        let ok = EntityFrame::new("t").with("best", blob(1)).with("any", "text");
        assert_eq!(c.check(&ok.attributes), Ok(()));
        let bad = EntityFrame::new("t").with("best", EntityFrame::new("b")).with("any", 1i64);
        assert!(matches!(
            c.check(&bad.attributes),
            Err(InvalidType::MissingAttribute { ref attribute, .. }) if attribute == "best.x"
        ));
    }

    #[test]
    fn unresolvable_element_type_is_reported_at_creation() {
        let mut r = TypeRegistry::new();
        r.create_entity_structure_type(
            "S",
            EntityStructureType::new("S").frame_seq("items", "Nope"),
        )
        .unwrap();
        assert!(matches!(
            TypeChecker::new(&r, "S"),
            Err(TypeRegistryError::NoSuchEntityStructureType { ref name, .. }) if name == "Nope"
        ));
    }

    #[test]
    fn recursive_types_resolve() {
        let mut r = TypeRegistry::new();
        r.create_entity_structure_type(
            "Tree",
            EntityStructureType::new("Tree").attr("v", ValueSort::Long).frame_seq("kids", "Tree"),
        )
        .unwrap();
        let c = TypeChecker::new(&r, "Tree").unwrap();
        let leaf = EntityFrame::new("l").with("v", 1i64).with("kids", Vec::<EntityFrame>::new());
        let root = EntityFrame::new("r").with("v", 0i64).with("kids", vec![leaf.clone(), leaf]);
        assert_eq!(c.check(&root.attributes), Ok(()));
    }
}
