//! Entity frames and entity structures (M3, seed Definitions 2.4.3–2.4.6, chapter 7).
//!
//! An [`EntityFrame`] is a name plus attribute/value pairs; a frame whose values contain
//! other frames is a recursive entity frame. An [`EntityStructure`] is an entity frame
//! stamped with the two times the seed adds to it: the valid time (when the content is
//! true of the world) and the create time (when the content was made).
//!
//! Attributes are a small ordered list, not a map: types have a handful of attributes,
//! a linear scan beats hashing at that size, and the order is the type's order, which
//! the archived form and printed output keep.

use rkyv::{Archive, Deserialize, Serialize};

use crate::time::Time;
use crate::value::Value;

/// One attribute and its value (`AttributeValuePair`).
#[derive(
    Debug, Clone, PartialEq, Archive, Serialize, Deserialize, serde::Serialize, serde::Deserialize,
)]
#[rkyv(derive(Debug))]
pub struct AttributeValuePair {
    /// The attribute's name, as declared in the entity structure type.
    pub name: String,
    /// Its value.
    pub value: Value,
}

impl AttributeValuePair {
    /// A pair from anything convertible to a [`Value`].
    pub fn new(name: impl Into<String>, value: impl Into<Value>) -> Self {
        Self { name: name.into(), value: value.into() }
    }
}

/// Looks an attribute up by name in a list of pairs.
pub fn find_attribute<'a>(attributes: &'a [AttributeValuePair], name: &str) -> Option<&'a Value> {
    attributes.iter().find(|p| p.name == name).map(|p| &p.value)
}

/// Attributes for the `create_at…` operations: from a `Vec` of pairs, a frame, or an
/// array of `(name, value)` tuples.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AttributeList(pub Vec<AttributeValuePair>);

impl From<Vec<AttributeValuePair>> for AttributeList {
    fn from(v: Vec<AttributeValuePair>) -> Self {
        AttributeList(v)
    }
}

impl From<EntityFrame> for AttributeList {
    fn from(f: EntityFrame) -> Self {
        AttributeList(f.attributes)
    }
}

impl<const N: usize> From<[(&str, Value); N]> for AttributeList {
    fn from(pairs: [(&str, Value); N]) -> Self {
        AttributeList(pairs.into_iter().map(|(n, v)| AttributeValuePair::new(n, v)).collect())
    }
}

/// A data structure representing an entity: a name and attribute/value pairs
/// (Definition 2.4.3). Frames nest through [`Value::EntityFrame`] and
/// [`Value::EntityFrameSeq`].
#[derive(
    Debug,
    Clone,
    PartialEq,
    Default,
    Archive,
    Serialize,
    Deserialize,
    serde::Serialize,
    serde::Deserialize,
)]
#[rkyv(derive(Debug))]
pub struct EntityFrame {
    /// The name of the represented entity (e.g. `blob3`), not of its type.
    pub name: String,
    /// The attribute/value pairs.
    pub attributes: Vec<AttributeValuePair>,
}

impl EntityFrame {
    /// An empty frame named `name`.
    pub fn new(name: impl Into<String>) -> Self {
        Self { name: name.into(), attributes: Vec::new() }
    }

    /// Builder form of [`EntityFrame::set`].
    #[must_use]
    pub fn with(mut self, attribute: impl Into<String>, value: impl Into<Value>) -> Self {
        self.set(attribute, value);
        self
    }

    /// Sets an attribute, replacing an earlier value of the same name.
    pub fn set(&mut self, attribute: impl Into<String>, value: impl Into<Value>) {
        set_attribute(&mut self.attributes, attribute.into(), value.into());
    }

    /// The value of an attribute, if present.
    pub fn get(&self, attribute: &str) -> Option<&Value> {
        find_attribute(&self.attributes, attribute)
    }
}

fn attributes_heap_bytes(
    attributes: &[AttributeValuePair],
    seen: &mut std::collections::HashSet<usize>,
) -> usize {
    attributes
        .iter()
        .map(|p| {
            std::mem::size_of::<AttributeValuePair>()
                + p.name.capacity()
                + p.value.approx_heap_bytes(seen)
        })
        .sum()
}

impl EntityFrame {
    /// Approximate heap bytes held (see [`Value::approx_heap_bytes`]).
    pub fn approx_heap_bytes(&self, seen: &mut std::collections::HashSet<usize>) -> usize {
        self.name.capacity() + attributes_heap_bytes(&self.attributes, seen)
    }
}

impl EntityStructure {
    /// Approximate bytes held, the structure itself included (see
    /// [`Value::approx_heap_bytes`]).
    pub fn approx_bytes(&self, seen: &mut std::collections::HashSet<usize>) -> usize {
        std::mem::size_of::<Self>()
            + self.name.capacity()
            + attributes_heap_bytes(&self.attributes, seen)
    }
}

fn set_attribute(attributes: &mut Vec<AttributeValuePair>, name: String, value: Value) {
    match attributes.iter_mut().find(|p| p.name == name) {
        Some(p) => p.value = value,
        None => attributes.push(AttributeValuePair { name, value }),
    }
}

/// An entity frame at a time-point: the unit stored in a trajectory (seed 2.4,
/// `struct EntityStructure`).
///
/// Two structures for one entity may share a valid time and differ in create time:
/// that is how the seed represents a later, better estimate of the same moment.
#[derive(
    Debug,
    Clone,
    PartialEq,
    Default,
    Archive,
    Serialize,
    Deserialize,
    serde::Serialize,
    serde::Deserialize,
)]
#[rkyv(derive(Debug))]
pub struct EntityStructure {
    /// The name of the represented entity.
    pub name: String,
    /// When the content is true of the world (Definition 3.3.4).
    pub valid_time: Time,
    /// When the content was created (Definition 3.3.5).
    pub create_time: Time,
    /// The attribute/value pairs, checked against the trajectory's type when added.
    pub attributes: Vec<AttributeValuePair>,
}

impl EntityStructure {
    /// A structure with no attributes yet (the seed's argument order: valid time, then
    /// create time). [`EntityStructure::named`] names both times instead.
    pub fn new(name: impl Into<String>, valid_time: Time, create_time: Time) -> Self {
        Self { name: name.into(), valid_time, create_time, attributes: Vec::new() }
    }

    /// A structure with no attributes and both times 0, to be given its times by name:
    ///
    /// ```
    /// use esgm_core::{EntityStructure, secs};
    /// let es = EntityStructure::named("robot").valid_at(secs(2)).created_at(secs(3)).with("x", 1.0);
    /// assert_eq!((es.valid_time, es.create_time), (secs(2), secs(3)));
    /// let same = EntityStructure::named("robot").at(secs(2));
    /// assert_eq!((same.valid_time, same.create_time), (secs(2), secs(2)));
    /// ```
    pub fn named(name: impl Into<String>) -> Self {
        Self::new(name, 0, 0)
    }

    /// Builder form: the valid time (when the content is true of the world).
    #[must_use]
    pub fn valid_at(mut self, valid_time: Time) -> Self {
        self.valid_time = valid_time;
        self
    }

    /// Builder form: the create time (when the content was made).
    #[must_use]
    pub fn created_at(mut self, create_time: Time) -> Self {
        self.create_time = create_time;
        self
    }

    /// Builder form: valid and created at `t` (a measurement stamped when taken).
    #[must_use]
    pub fn at(self, t: Time) -> Self {
        self.valid_at(t).created_at(t)
    }

    /// A structure from a frame and its two times.
    pub fn from_frame(frame: EntityFrame, valid_time: Time, create_time: Time) -> Self {
        Self { name: frame.name, valid_time, create_time, attributes: frame.attributes }
    }

    /// Builder form of [`EntityStructure::set`].
    #[must_use]
    pub fn with(mut self, attribute: impl Into<String>, value: impl Into<Value>) -> Self {
        self.set(attribute, value);
        self
    }

    /// Sets an attribute, replacing an earlier value of the same name.
    pub fn set(&mut self, attribute: impl Into<String>, value: impl Into<Value>) {
        set_attribute(&mut self.attributes, attribute.into(), value.into());
    }

    /// The value of an attribute, if present.
    pub fn get(&self, attribute: &str) -> Option<&Value> {
        find_attribute(&self.attributes, attribute)
    }

    /// The structure's name and attributes as a frame (dropping the times), e.g. to nest
    /// it inside another structure.
    pub fn to_frame(&self) -> EntityFrame {
        EntityFrame { name: self.name.clone(), attributes: self.attributes.clone() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_replaces_and_get_finds() {
        let mut es = EntityStructure::new("robot1", 10, 11).with("x", 1.0).with("y", 2.0);
        es.set("x", 3.0);
        assert_eq!(es.attributes.len(), 2);
        assert_eq!(es.get("x"), Some(&Value::Double(3.0)));
        assert_eq!(es.get("z"), None);
        let f = es.to_frame();
        assert_eq!(EntityStructure::from_frame(f, 10, 11), es);
    }
}
