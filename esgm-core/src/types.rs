//! Entity structure types (M4, seed 2.4.1 and 7.1): a name and typed attributes.

use rkyv::{Archive, Deserialize, Serialize};

use crate::value::ValueSort;

/// One typed attribute of an entity structure type (the seed's `Attr`).
///
/// A frame-sorted attribute ([`ValueSort::EntityFrame`] or
/// [`ValueSort::EntityFrameSeq`]) may name the registered type of its element(s); then
/// nested frames are type-checked too. Without it, any frame is accepted there.
#[derive(
    Debug,
    Clone,
    PartialEq,
    Eq,
    Hash,
    Archive,
    Serialize,
    Deserialize,
    serde::Serialize,
    serde::Deserialize,
)]
#[rkyv(derive(Debug))]
pub struct Attr {
    /// The attribute's name, unique within its type.
    pub name: String,
    /// The sort every value of the attribute must have (IDL field `type`).
    pub sort: ValueSort,
    /// For frame-sorted attributes: the registered type name of the nested frame(s).
    pub element_type: Option<String>,
}

impl Attr {
    /// An attribute of the given sort.
    pub fn new(name: impl Into<String>, sort: ValueSort) -> Self {
        Self { name: name.into(), sort, element_type: None }
    }
}

/// The type of the structures in a trajectory: a name and the attributes every
/// instance must assign (the seed's `EntityStructureType`).
#[derive(
    Debug,
    Clone,
    PartialEq,
    Eq,
    Hash,
    Archive,
    Serialize,
    Deserialize,
    serde::Serialize,
    serde::Deserialize,
)]
#[rkyv(derive(Debug))]
pub struct EntityStructureType {
    /// The type's own name (the seed's tutorial registers `BlobType` under `blob`; the
    /// registry key is what trajectories and element types refer to).
    pub name: String,
    /// The attributes, in declaration order.
    pub attributes: Vec<Attr>,
}

/// Why a type definition is unusable.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub enum TypeDefinitionError {
    /// Two attributes share a name; rename one.
    #[error("type `{type_name}` declares attribute `{attribute}` twice")]
    DuplicateAttribute {
        /// The type.
        type_name: String,
        /// The repeated attribute.
        attribute: String,
    },
    /// An element type was given for an attribute that holds no frames.
    #[error(
        "attribute `{attribute}` of type `{type_name}` has sort {sort} and cannot name an element type"
    )]
    ElementTypeOnNonFrame {
        /// The type.
        type_name: String,
        /// The attribute.
        attribute: String,
        /// Its (non-frame) sort.
        sort: ValueSort,
    },
    /// A name is empty; every type and attribute needs one.
    #[error("type `{type_name}` has an empty {what} name")]
    EmptyName {
        /// The type (may itself be empty).
        type_name: String,
        /// `type` or `attribute`.
        what: String,
    },
    /// [`ValueSort::NoValue`] is the sort of a missing value and cannot be declared.
    #[error("attribute `{attribute}` of type `{type_name}` cannot have sort NoValue")]
    NoValueSort {
        /// The type.
        type_name: String,
        /// The attribute.
        attribute: String,
    },
}

impl EntityStructureType {
    /// A type with no attributes yet; add them with [`EntityStructureType::attr`] and
    /// friends.
    pub fn new(name: impl Into<String>) -> Self {
        Self { name: name.into(), attributes: Vec::new() }
    }

    /// Adds an attribute of `sort`.
    #[must_use]
    pub fn attr(mut self, name: impl Into<String>, sort: ValueSort) -> Self {
        self.attributes.push(Attr::new(name, sort));
        self
    }

    /// Adds a nested-frame attribute whose frame must be of the registered type
    /// `element_type`.
    #[must_use]
    pub fn frame(mut self, name: impl Into<String>, element_type: impl Into<String>) -> Self {
        self.attributes.push(Attr {
            name: name.into(),
            sort: ValueSort::EntityFrame,
            element_type: Some(element_type.into()),
        });
        self
    }

    /// Adds a frame-sequence attribute whose frames must be of the registered type
    /// `element_type`.
    #[must_use]
    pub fn frame_seq(mut self, name: impl Into<String>, element_type: impl Into<String>) -> Self {
        self.attributes.push(Attr {
            name: name.into(),
            sort: ValueSort::EntityFrameSeq,
            element_type: Some(element_type.into()),
        });
        self
    }

    /// The declared attribute called `name`.
    pub fn attribute(&self, name: &str) -> Option<&Attr> {
        self.attributes.iter().find(|a| a.name == name)
    }

    /// Checks the definition is self-consistent (unique non-empty names, element types
    /// only on frame attributes). Element types are resolved later, against a registry.
    pub fn validate(&self) -> Result<(), TypeDefinitionError> {
        if self.name.is_empty() {
            return Err(TypeDefinitionError::EmptyName {
                type_name: String::new(),
                what: "type".into(),
            });
        }
        for (i, a) in self.attributes.iter().enumerate() {
            let err_ctx = || (self.name.clone(), a.name.clone());
            if a.name.is_empty() {
                return Err(TypeDefinitionError::EmptyName {
                    type_name: self.name.clone(),
                    what: "attribute".into(),
                });
            }
            if self.attributes[..i].iter().any(|b| b.name == a.name) {
                let (type_name, attribute) = err_ctx();
                return Err(TypeDefinitionError::DuplicateAttribute { type_name, attribute });
            }
            if a.sort == ValueSort::NoValue {
                let (type_name, attribute) = err_ctx();
                return Err(TypeDefinitionError::NoValueSort { type_name, attribute });
            }
            if a.element_type.is_some()
                && !matches!(a.sort, ValueSort::EntityFrame | ValueSort::EntityFrameSeq)
            {
                let (type_name, attribute) = err_ctx();
                return Err(TypeDefinitionError::ElementTypeOnNonFrame {
                    type_name,
                    attribute,
                    sort: a.sort,
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builder_and_validation() {
        let t = EntityStructureType::new("BlobSeq").frame_seq("items", "Blob");
        assert!(t.validate().is_ok());
        assert_eq!(t.attribute("items").map(|a| a.sort), Some(ValueSort::EntityFrameSeq));

        let dup =
            EntityStructureType::new("T").attr("x", ValueSort::Long).attr("x", ValueSort::Long);
        assert!(matches!(dup.validate(), Err(TypeDefinitionError::DuplicateAttribute { .. })));

        let mut bad = EntityStructureType::new("T").attr("x", ValueSort::Long);
        bad.attributes[0].element_type = Some("Blob".into());
        assert!(matches!(bad.validate(), Err(TypeDefinitionError::ElementTypeOnNonFrame { .. })));

        assert!(EntityStructureType::new("").validate().is_err());
        assert!(EntityStructureType::new("T").attr("", ValueSort::Long).validate().is_err());
        assert!(EntityStructureType::new("T").attr("n", ValueSort::NoValue).validate().is_err());
    }
}
