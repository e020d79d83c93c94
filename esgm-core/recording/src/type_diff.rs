//! How two definitions of one type differ: the first attribute that does, in words.
//!
//! One implementation for everyone who must refuse or report a type mismatch between
//! a recording and something else ([`crate::compare()`] between two recordings,
//! [`crate::load()`] between a recording and an ESGM), so a mismatch is named the same
//! way everywhere.

use esgm_core::EntityStructureType;

use crate::layout::TypeSchema;

/// The first difference between two definitions of a type.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct TypeDifference {
    /// The type's registered name.
    pub type_name: String,
    /// The first attribute that differs, if an attribute does (`None` when only the
    /// type's own name does).
    pub attribute: Option<String>,
    /// How it differs, for people, with `left` and `right` as the caller calls the two
    /// sides ("in A … in B", "recorded … in the ESGM").
    pub detail: String,
}

impl std::fmt::Display for TypeDifference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.attribute {
            Some(a) => write!(f, "type `{}`, attribute `{a}`: {}", self.type_name, self.detail),
            None => write!(f, "type `{}`: {}", self.type_name, self.detail),
        }
    }
}

/// The first difference between `left` and `right`, two definitions registered as
/// `type_name`, or `None` if they are equal. `sides` names the two in the detail
/// (e.g. `("recorded", "in the ESGM")`).
pub fn type_difference(
    type_name: &str,
    left: &EntityStructureType,
    right: &EntityStructureType,
    sides: (&str, &str),
) -> Option<TypeDifference> {
    let (l, r) = sides;
    let diff = |attribute: Option<&str>, detail: String| {
        Some(TypeDifference {
            type_name: type_name.to_owned(),
            attribute: attribute.map(str::to_owned),
            detail,
        })
    };
    for (i, la) in left.attributes.iter().enumerate() {
        let Some(ra) = right.attributes.iter().find(|a| a.name == la.name) else {
            return diff(Some(&la.name), format!("{l} it exists, {r} it does not"));
        };
        if la.sort != ra.sort {
            return diff(Some(&la.name), format!("sort {} {l}, {} {r}", la.sort, ra.sort));
        }
        if la.element_type != ra.element_type {
            let show = |e: &Option<String>| e.clone().unwrap_or_else(|| "none".into());
            return diff(
                Some(&la.name),
                format!(
                    "element type {} {l}, {} {r}",
                    show(&la.element_type),
                    show(&ra.element_type)
                ),
            );
        }
        if right.attributes.get(i).map(|a| &a.name) != Some(&la.name) {
            return diff(
                Some(&la.name),
                format!("it is attribute {i} {l}, at another position {r}"),
            );
        }
    }
    if let Some(ra) =
        right.attributes.iter().find(|ra| !left.attributes.iter().any(|la| la.name == ra.name))
    {
        return diff(Some(&ra.name), format!("{l} it does not exist, {r} it does"));
    }
    if left.name != right.name {
        return diff(None, format!("its own name is `{}` {l}, `{}` {r}", left.name, right.name));
    }
    None
}

/// Every type a schema needs, by registered name: the root (registered as
/// `root_name`, its trajectory's type name) and each nested type.
pub fn schema_types<'a>(
    root_name: &'a str,
    schema: &'a TypeSchema,
) -> Vec<(&'a str, &'a EntityStructureType)> {
    let mut v = vec![(root_name, &schema.root)];
    v.extend(schema.nested.iter().map(|(n, t)| (n.as_str(), t)));
    v
}

/// The first difference between two recorded schemas of one trajectory: its type
/// name, then the root and each nested type. A nested type present in one schema
/// only is a difference too.
pub fn schema_difference(
    left: (&str, &TypeSchema),
    right: (&str, &TypeSchema),
    sides: (&str, &str),
) -> Option<TypeDifference> {
    let (l, r) = sides;
    if left.0 != right.0 {
        return Some(TypeDifference {
            type_name: left.0.to_owned(),
            attribute: None,
            detail: format!("the trajectory's type is `{}` {l}, `{}` {r}", left.0, right.0),
        });
    }
    if let Some(d) = type_difference(left.0, &left.1.root, &right.1.root, sides) {
        return Some(d);
    }
    for (name, lt) in &left.1.nested {
        match right.1.nested.get(name) {
            Some(rt) => {
                if let Some(d) = type_difference(name, lt, rt, sides) {
                    return Some(d);
                }
            }
            None => {
                return Some(TypeDifference {
                    type_name: name.clone(),
                    attribute: None,
                    detail: format!("nested type known {l}, not {r}"),
                });
            }
        }
    }
    right.1.nested.keys().find(|n| !left.1.nested.contains_key(*n)).map(|name| TypeDifference {
        type_name: name.clone(),
        attribute: None,
        detail: format!("nested type known {r}, not {l}"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::{Attr, ValueSort};

    fn ty(attrs: &[(&str, ValueSort)]) -> EntityStructureType {
        EntityStructureType {
            name: "T".into(),
            attributes: attrs.iter().map(|(n, s)| Attr::new(*n, *s)).collect(),
        }
    }

    #[test]
    fn names_the_first_differing_attribute() {
        let a = ty(&[("x", ValueSort::Double), ("y", ValueSort::Double)]);
        assert_eq!(type_difference("T", &a, &a.clone(), ("in A", "in B")), None);
        let b = ty(&[("x", ValueSort::Double), ("y", ValueSort::Long)]);
        let d = type_difference("T", &a, &b, ("in A", "in B")).expect("differs");
        assert_eq!(d.attribute.as_deref(), Some("y"));
        assert!(d.detail.contains("Double in A") && d.detail.contains("Long in B"), "{d}");
        let c = ty(&[("x", ValueSort::Double)]);
        let d = type_difference("T", &a, &c, ("in A", "in B")).expect("differs");
        assert_eq!(d.attribute.as_deref(), Some("y"));
        let d = type_difference("T", &c, &a, ("in A", "in B")).expect("differs");
        assert_eq!(d.attribute.as_deref(), Some("y"));
        let swapped = ty(&[("y", ValueSort::Double), ("x", ValueSort::Double)]);
        let d = type_difference("T", &a, &swapped, ("in A", "in B")).expect("order differs");
        assert_eq!(d.attribute.as_deref(), Some("x"));
    }
}
