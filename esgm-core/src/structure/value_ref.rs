//! Reading an attribute's value where it lies: [`ValueRef`] (a value), [`FrameRef`] (a
//! nested frame), [`FramesRef`] (a frame sequence) and [`Attributes`] (a structure's or
//! frame's pairs), each over an owned [`Value`] or an archived one alike.
//!
//! Numbers, booleans and times are copied out (a load each); strings and byte
//! sequences are borrowed where they lie; an octet sequence can be taken as a shared
//! [`Octets`] that keeps its archive alive instead of copying it. Only
//! [`ValueRef::to_value`] (and what calls it) builds an owned value.

use std::borrow::Cow;
use std::fmt;
use std::sync::Arc;

use crate::codec::{ArchivedAttributeValuePair, ArchivedEntityFrame, ArchivedValue};
use crate::octets::{Octets, OctetsHolder};
use crate::value::frame::{AttributeValuePair, EntityFrame};
use crate::value::{
    Pos2, Position, PositionAltitude, PositionAltitudeRotation, Rotation, Value, ValueSort, Vec3,
};

/// An attribute's value, read in place (see the module docs).
#[derive(Clone, Copy)]
pub struct ValueRef<'a>(Inner<'a>);

#[derive(Clone, Copy)]
enum Inner<'a> {
    Owned(&'a Value),
    Archived { value: &'a ArchivedValue, holder: &'a Arc<dyn OctetsHolder> },
}

impl<'a> From<&'a Value> for ValueRef<'a> {
    fn from(v: &'a Value) -> Self {
        ValueRef(Inner::Owned(v))
    }
}

impl<'a> ValueRef<'a> {
    /// An archived value inside `holder`'s bytes.
    pub(crate) fn archived(value: &'a ArchivedValue, holder: &'a Arc<dyn OctetsHolder>) -> Self {
        ValueRef(Inner::Archived { value, holder })
    }

    /// The value's sort.
    pub fn sort(self) -> ValueSort {
        match self.0 {
            Inner::Owned(v) => v.sort(),
            Inner::Archived { value, .. } => archived_sort(value),
        }
    }

    /// True for the special value "no value".
    pub fn is_no_value(self) -> bool {
        self.sort() == ValueSort::NoValue
    }

    /// The value as an integer, if it is a `Long` or a `Time`.
    pub fn as_long(self) -> Option<i64> {
        match self.0 {
            Inner::Owned(v) => v.as_long(),
            Inner::Archived { value, .. } => match value {
                ArchivedValue::Long(v) | ArchivedValue::Time(v) => Some(v.to_native()),
                _ => None,
            },
        }
    }

    /// The value as a float, if it is a number of any sort (`Long`, `Double`, `Time`,
    /// `Altitude`).
    pub fn as_double(self) -> Option<f64> {
        match self.0 {
            Inner::Owned(v) => v.as_double(),
            Inner::Archived { value, .. } => match value {
                ArchivedValue::Double(v) | ArchivedValue::Altitude(v) => Some(v.to_native()),
                ArchivedValue::Long(v) | ArchivedValue::Time(v) => Some(v.to_native() as f64),
                _ => None,
            },
        }
    }

    /// The value as a bool, if it is one.
    pub fn as_bool(self) -> Option<bool> {
        match self.0 {
            Inner::Owned(v) => v.as_bool(),
            Inner::Archived { value: ArchivedValue::Bool(b), .. } => Some(*b),
            Inner::Archived { .. } => None,
        }
    }

    /// The text of a `String` or a `Symbol`, where it lies.
    pub fn as_str(self) -> Option<&'a str> {
        match self.0 {
            Inner::Owned(v) => v.as_str(),
            Inner::Archived { value, .. } => match value {
                ArchivedValue::String(s) | ArchivedValue::Symbol(s) => Some(s.as_str()),
                _ => None,
            },
        }
    }

    /// The bytes of an octet sequence (an image's pixels), where they lie.
    pub fn as_bytes(self) -> Option<&'a [u8]> {
        match self.0 {
            Inner::Owned(v) => v.as_octets().map(|o| &o[..]),
            Inner::Archived { value: ArchivedValue::OctetSeq(o), .. } => Some(o.as_slice()),
            Inner::Archived { .. } => None,
        }
    }

    /// An octet sequence as a shared [`Octets`] that may outlive this reference: it
    /// shares the owned bytes, or holds the archive the bytes lie in. Never a copy,
    /// unless the archive's holder does not contain them (then they are copied).
    pub fn as_octets(self) -> Option<Octets> {
        match self.0 {
            Inner::Owned(v) => v.as_octets().cloned(),
            Inner::Archived { value: ArchivedValue::OctetSeq(o), holder } => {
                Some(held(holder, o.as_slice()))
            }
            Inner::Archived { .. } => None,
        }
    }

    /// The nested frame of an `EntityFrame` value.
    pub fn as_frame(self) -> Option<FrameRef<'a>> {
        match self.0 {
            Inner::Owned(v) => v.as_frame().map(FrameRef::owned),
            Inner::Archived { value: ArchivedValue::EntityFrame(f), holder } => {
                Some(FrameRef::archived(f, holder))
            }
            Inner::Archived { .. } => None,
        }
    }

    /// The frames of an `EntityFrameSeq` value.
    pub fn as_frames(self) -> Option<FramesRef<'a>> {
        match self.0 {
            Inner::Owned(v) => v.as_frames().map(|f| FramesRef(FramesInner::Owned(f))),
            Inner::Archived { value: ArchivedValue::EntityFrameSeq(f), holder } => {
                Some(FramesRef(FramesInner::Archived { frames: f.as_slice(), holder }))
            }
            Inner::Archived { .. } => None,
        }
    }

    /// The elements of an `Agg` or `Collection` value, each read in place.
    pub fn elements(self) -> Option<impl ExactSizeIterator<Item = ValueRef<'a>> + 'a> {
        enum Either<A, B> {
            A(A),
            B(B),
        }
        impl<T, A: Iterator<Item = T>, B: Iterator<Item = T>> Iterator for Either<A, B> {
            type Item = T;
            fn next(&mut self) -> Option<T> {
                match self {
                    Either::A(a) => a.next(),
                    Either::B(b) => b.next(),
                }
            }
            fn size_hint(&self) -> (usize, Option<usize>) {
                match self {
                    Either::A(a) => a.size_hint(),
                    Either::B(b) => b.size_hint(),
                }
            }
        }
        impl<T, A: ExactSizeIterator<Item = T>, B: ExactSizeIterator<Item = T>> ExactSizeIterator
            for Either<A, B>
        {
        }
        match self.0 {
            Inner::Owned(Value::Agg(v) | Value::Collection(v)) => {
                Some(Either::A(v.iter().map(ValueRef::from)))
            }
            Inner::Archived {
                value: ArchivedValue::Agg(v) | ArchivedValue::Collection(v),
                holder,
            } => Some(Either::B(v.iter().map(move |x| ValueRef::archived(x, holder)))),
            _ => None,
        }
    }

    /// A `LongSeq`'s numbers: borrowed where they lie (on a little-endian host, where
    /// the archived form is the native one), copied otherwise.
    pub fn as_long_seq(self) -> Option<Cow<'a, [i64]>> {
        match self.0 {
            Inner::Owned(Value::LongSeq(v)) => Some(Cow::Borrowed(v)),
            Inner::Archived { value: ArchivedValue::LongSeq(v), .. } => {
                Some(native_slice(v.as_slice(), |x| x.to_native()))
            }
            _ => None,
        }
    }

    /// A `DoubleSeq`'s numbers, as [`Self::as_long_seq`].
    pub fn as_double_seq(self) -> Option<Cow<'a, [f64]>> {
        match self.0 {
            Inner::Owned(Value::DoubleSeq(v)) => Some(Cow::Borrowed(v)),
            Inner::Archived { value: ArchivedValue::DoubleSeq(v), .. } => {
                Some(native_slice(v.as_slice(), |x| x.to_native()))
            }
            _ => None,
        }
    }

    /// A `SymbolSeq`'s symbols, each borrowed where it lies.
    pub fn symbols(self) -> Option<Vec<&'a str>> {
        match self.0 {
            Inner::Owned(Value::SymbolSeq(v)) => Some(v.iter().map(String::as_str).collect()),
            Inner::Archived { value: ArchivedValue::SymbolSeq(v), .. } => {
                Some(v.iter().map(|s| s.as_str()).collect())
            }
            _ => None,
        }
    }

    /// The number of items of a sequence value (bytes of an octet sequence, numbers,
    /// symbols, vectors, points, values of an `Agg` or `Collection`, frames of a frame
    /// sequence); `None` for a value that is not a sequence.
    pub fn seq_len(self) -> Option<usize> {
        Some(match self.0 {
            Inner::Owned(v) => match v {
                Value::OctetSeq(x) => x.len(),
                Value::LongSeq(x) => x.len(),
                Value::DoubleSeq(x) => x.len(),
                Value::SymbolSeq(x) => x.len(),
                Value::VecSeq(x) => x.len(),
                Value::Pos2Seq(x) => x.len(),
                Value::Agg(x) | Value::Collection(x) => x.len(),
                Value::EntityFrameSeq(x) => x.len(),
                _ => return None,
            },
            Inner::Archived { value, .. } => match value {
                ArchivedValue::OctetSeq(x) => x.as_slice().len(),
                ArchivedValue::LongSeq(x) => x.len(),
                ArchivedValue::DoubleSeq(x) => x.len(),
                ArchivedValue::SymbolSeq(x) => x.len(),
                ArchivedValue::VecSeq(x) => x.len(),
                ArchivedValue::Pos2Seq(x) => x.len(),
                ArchivedValue::Agg(x) | ArchivedValue::Collection(x) => x.len(),
                ArchivedValue::EntityFrameSeq(x) => x.len(),
                _ => return None,
            },
        })
    }

    /// Symbol `i` of a `SymbolSeq`, where it lies.
    pub fn symbol_at(self, i: usize) -> Option<&'a str> {
        match self.0 {
            Inner::Owned(Value::SymbolSeq(v)) => v.get(i).map(String::as_str),
            Inner::Archived { value: ArchivedValue::SymbolSeq(v), .. } => {
                v.get(i).map(|s| s.as_str())
            }
            _ => None,
        }
    }

    /// Vector `i` of a `VecSeq`.
    pub fn vec3_at(self, i: usize) -> Option<Vec3> {
        match self.0 {
            Inner::Owned(Value::VecSeq(v)) => v.get(i).copied(),
            Inner::Archived { value: ArchivedValue::VecSeq(v), .. } => v.get(i).map(vec3),
            _ => None,
        }
    }

    /// Point `i` of a `Pos2Seq`.
    pub fn pos2_at(self, i: usize) -> Option<Pos2> {
        match self.0 {
            Inner::Owned(Value::Pos2Seq(v)) => v.get(i).copied(),
            Inner::Archived { value: ArchivedValue::Pos2Seq(v), .. } => {
                v.get(i).map(|p| Pos2 { x: p.x.to_native(), y: p.y.to_native() })
            }
            _ => None,
        }
    }

    /// True if an octet sequence's bytes lie outside this process's heap (in another
    /// process's shared memory, read in place); false on the heap, or for another sort.
    pub fn octets_are_shared(self) -> bool {
        match self.0 {
            Inner::Owned(Value::OctetSeq(o)) => o.is_held(),
            Inner::Archived { value: ArchivedValue::OctetSeq(_), holder } => !holder.on_heap(),
            _ => false,
        }
    }

    /// A `Vec` value.
    pub fn as_vec3(self) -> Option<Vec3> {
        match self.0 {
            Inner::Owned(Value::Vec(v)) => Some(*v),
            Inner::Archived { value: ArchivedValue::Vec(v), .. } => Some(vec3(v)),
            _ => None,
        }
    }

    /// A `Pos2` value.
    pub fn as_pos2(self) -> Option<Pos2> {
        match self.0 {
            Inner::Owned(Value::Pos2(p)) => Some(*p),
            Inner::Archived { value: ArchivedValue::Pos2(p), .. } => {
                Some(Pos2 { x: p.x.to_native(), y: p.y.to_native() })
            }
            _ => None,
        }
    }

    /// A `Position` value.
    pub fn as_position(self) -> Option<Position> {
        match self.0 {
            Inner::Owned(Value::Position(p)) => Some(*p),
            Inner::Archived { value: ArchivedValue::Position(p), .. } => Some(position(p)),
            _ => None,
        }
    }

    /// A `Rotation` value.
    pub fn as_rotation(self) -> Option<Rotation> {
        match self.0 {
            Inner::Owned(Value::Rotation(r)) => Some(*r),
            Inner::Archived { value: ArchivedValue::Rotation(r), .. } => Some(rotation(r)),
            _ => None,
        }
    }

    /// A `PositionAltitude` value.
    pub fn as_position_altitude(self) -> Option<PositionAltitude> {
        match self.0 {
            Inner::Owned(Value::PositionAltitude(p)) => Some(*p),
            Inner::Archived { value: ArchivedValue::PositionAltitude(p), .. } => {
                Some(PositionAltitude {
                    position: position(&p.position),
                    altitude: p.altitude.to_native(),
                })
            }
            _ => None,
        }
    }

    /// A `PositionAltitudeRotation` value (a full pose).
    pub fn as_pose(self) -> Option<PositionAltitudeRotation> {
        match self.0 {
            Inner::Owned(Value::PositionAltitudeRotation(p)) => Some(*p),
            Inner::Archived { value: ArchivedValue::PositionAltitudeRotation(p), .. } => {
                Some(PositionAltitudeRotation {
                    position: position(&p.position),
                    altitude: p.altitude.to_native(),
                    rotation: rotation(&p.rotation),
                })
            }
            _ => None,
        }
    }

    /// The owned value when it is one (a structure made in this process).
    pub fn as_value(self) -> Option<&'a Value> {
        match self.0 {
            Inner::Owned(v) => Some(v),
            Inner::Archived { .. } => None,
        }
    }

    /// The archived value when it is one, read in place.
    pub fn as_archived(self) -> Option<&'a ArchivedValue> {
        match self.0 {
            Inner::Archived { value, .. } => Some(value),
            Inner::Owned(_) => None,
        }
    }

    /// An owned copy of the value; octet sequences stay where they lie (held), so an
    /// image is never copied by it.
    pub fn to_value(self) -> Value {
        match self.0 {
            Inner::Owned(v) => v.clone(),
            Inner::Archived { value, holder } => owned_value(value, holder),
        }
    }
}

impl PartialEq for ValueRef<'_> {
    fn eq(&self, other: &Self) -> bool {
        match (self.0, other.0) {
            (Inner::Owned(a), Inner::Owned(b)) => a == b,
            _ => self.to_value() == other.to_value(),
        }
    }
}

impl PartialEq<Value> for ValueRef<'_> {
    fn eq(&self, other: &Value) -> bool {
        match self.0 {
            Inner::Owned(v) => v == other,
            Inner::Archived { .. } => self.to_value() == *other,
        }
    }
}

impl PartialEq<&Value> for ValueRef<'_> {
    fn eq(&self, other: &&Value) -> bool {
        *self == **other
    }
}

impl fmt::Debug for ValueRef<'_> {
    // Through the owned value: it prints an image as its length, never its pixels.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Inner::Owned(v) => fmt::Debug::fmt(v, f),
            Inner::Archived { .. } => fmt::Debug::fmt(&self.to_value(), f),
        }
    }
}

/// A nested entity frame, read in place.
#[derive(Clone, Copy)]
pub struct FrameRef<'a>(FrameInner<'a>);

#[derive(Clone, Copy)]
enum FrameInner<'a> {
    Owned(&'a EntityFrame),
    Archived { frame: &'a ArchivedEntityFrame, holder: &'a Arc<dyn OctetsHolder> },
}

impl<'a> FrameRef<'a> {
    fn owned(frame: &'a EntityFrame) -> Self {
        FrameRef(FrameInner::Owned(frame))
    }

    fn archived(frame: &'a ArchivedEntityFrame, holder: &'a Arc<dyn OctetsHolder>) -> Self {
        FrameRef(FrameInner::Archived { frame, holder })
    }

    /// The represented entity's name.
    pub fn name(self) -> &'a str {
        match self.0 {
            FrameInner::Owned(f) => &f.name,
            FrameInner::Archived { frame, .. } => frame.name.as_str(),
        }
    }

    /// The value of an attribute, read in place.
    pub fn get(self, attribute: &str) -> Option<ValueRef<'a>> {
        self.attributes().find(|(name, _)| *name == attribute).map(|(_, v)| v)
    }

    /// The frame's attribute/value pairs, in order.
    pub fn attributes(self) -> Attributes<'a> {
        match self.0 {
            FrameInner::Owned(f) => Attributes::owned(&f.attributes),
            FrameInner::Archived { frame, holder } => {
                Attributes::archived(&frame.attributes, holder)
            }
        }
    }

    /// An owned copy of the frame (octet sequences held where they lie).
    pub fn to_frame(self) -> EntityFrame {
        match self.0 {
            FrameInner::Owned(f) => f.clone(),
            FrameInner::Archived { .. } => EntityFrame {
                name: self.name().to_owned(),
                attributes: self.attributes().to_pairs(),
            },
        }
    }
}

impl fmt::Debug for FrameRef<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Frame")
            .field("name", &self.name())
            .field("attributes", &self.attributes().debug())
            .finish()
    }
}

/// A sequence of entity frames, read in place.
#[derive(Clone, Copy)]
pub struct FramesRef<'a>(FramesInner<'a>);

#[derive(Clone, Copy)]
enum FramesInner<'a> {
    Owned(&'a [EntityFrame]),
    Archived { frames: &'a [ArchivedEntityFrame], holder: &'a Arc<dyn OctetsHolder> },
}

impl<'a> FramesRef<'a> {
    /// How many frames there are.
    pub fn len(self) -> usize {
        match self.0 {
            FramesInner::Owned(f) => f.len(),
            FramesInner::Archived { frames, .. } => frames.len(),
        }
    }

    /// True if there are none.
    pub fn is_empty(self) -> bool {
        self.len() == 0
    }

    /// The `i`-th frame.
    pub fn get(self, i: usize) -> Option<FrameRef<'a>> {
        match self.0 {
            FramesInner::Owned(f) => f.get(i).map(FrameRef::owned),
            FramesInner::Archived { frames, holder } => {
                frames.get(i).map(|f| FrameRef::archived(f, holder))
            }
        }
    }

    /// The frames in order.
    pub fn iter(self) -> impl ExactSizeIterator<Item = FrameRef<'a>> + 'a {
        (0..self.len()).filter_map(move |i| self.get(i)).collect::<Vec<_>>().into_iter()
    }

    /// Owned copies of the frames (octet sequences held where they lie).
    pub fn to_frames(self) -> Vec<EntityFrame> {
        match self.0 {
            FramesInner::Owned(f) => f.to_vec(),
            FramesInner::Archived { .. } => self.iter().map(FrameRef::to_frame).collect(),
        }
    }
}

impl fmt::Debug for FramesRef<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

/// The attribute/value pairs of a structure or frame, read in place, in order.
#[derive(Clone)]
pub struct Attributes<'a>(AttributesInner<'a>);

#[derive(Clone)]
enum AttributesInner<'a> {
    Owned(std::slice::Iter<'a, AttributeValuePair>),
    Archived {
        pairs: std::slice::Iter<'a, ArchivedAttributeValuePair>,
        holder: &'a Arc<dyn OctetsHolder>,
    },
}

impl<'a> Attributes<'a> {
    pub(crate) fn owned(pairs: &'a [AttributeValuePair]) -> Self {
        Attributes(AttributesInner::Owned(pairs.iter()))
    }

    pub(crate) fn archived(
        pairs: &'a [ArchivedAttributeValuePair],
        holder: &'a Arc<dyn OctetsHolder>,
    ) -> Self {
        Attributes(AttributesInner::Archived { pairs: pairs.iter(), holder })
    }

    /// No pairs at all (a frame that is not there).
    pub fn none() -> Attributes<'static> {
        Attributes(AttributesInner::Owned([].iter()))
    }

    /// Owned copies of the pairs (octet sequences held where they lie).
    pub fn to_pairs(self) -> Vec<AttributeValuePair> {
        self.map(|(name, v)| AttributeValuePair { name: name.to_owned(), value: v.to_value() })
            .collect()
    }

    pub(crate) fn debug(self) -> impl fmt::Debug + 'a {
        struct Pairs<'a>(Attributes<'a>);
        impl fmt::Debug for Pairs<'_> {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.debug_map().entries(self.0.clone()).finish()
            }
        }
        Pairs(self)
    }
}

impl fmt::Debug for Attributes<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&self.clone().debug(), f)
    }
}

impl<'a> Iterator for Attributes<'a> {
    type Item = (&'a str, ValueRef<'a>);

    fn next(&mut self) -> Option<Self::Item> {
        match &mut self.0 {
            AttributesInner::Owned(it) => it.next().map(|p| (p.name.as_str(), (&p.value).into())),
            AttributesInner::Archived { pairs, holder } => {
                let holder = *holder;
                pairs.next().map(|p| (p.name.as_str(), ValueRef::archived(&p.value, holder)))
            }
        }
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        match &self.0 {
            AttributesInner::Owned(it) => it.size_hint(),
            AttributesInner::Archived { pairs, .. } => pairs.size_hint(),
        }
    }

    fn nth(&mut self, n: usize) -> Option<Self::Item> {
        match &mut self.0 {
            AttributesInner::Owned(it) => it.nth(n).map(|p| (p.name.as_str(), (&p.value).into())),
            AttributesInner::Archived { pairs, holder } => {
                let holder = *holder;
                pairs.nth(n).map(|p| (p.name.as_str(), ValueRef::archived(&p.value, holder)))
            }
        }
    }
}

impl ExactSizeIterator for Attributes<'_> {}

/// The sort of an archived value, read from its tag alone.
pub(crate) fn archived_sort(value: &ArchivedValue) -> ValueSort {
    match value {
        ArchivedValue::NoValue => ValueSort::NoValue,
        ArchivedValue::Long(_) => ValueSort::Long,
        ArchivedValue::Double(_) => ValueSort::Double,
        ArchivedValue::Bool(_) => ValueSort::Bool,
        ArchivedValue::String(_) => ValueSort::String,
        ArchivedValue::Time(_) => ValueSort::Time,
        ArchivedValue::Symbol(_) => ValueSort::Symbol,
        ArchivedValue::OctetSeq(_) => ValueSort::OctetSeq,
        ArchivedValue::LongSeq(_) => ValueSort::LongSeq,
        ArchivedValue::DoubleSeq(_) => ValueSort::DoubleSeq,
        ArchivedValue::SymbolSeq(_) => ValueSort::SymbolSeq,
        ArchivedValue::Vec(_) => ValueSort::Vec,
        ArchivedValue::VecSeq(_) => ValueSort::VecSeq,
        ArchivedValue::Pos2(_) => ValueSort::Pos2,
        ArchivedValue::Pos2Seq(_) => ValueSort::Pos2Seq,
        ArchivedValue::Position(_) => ValueSort::Position,
        ArchivedValue::Altitude(_) => ValueSort::Altitude,
        ArchivedValue::Rotation(_) => ValueSort::Rotation,
        ArchivedValue::PositionAltitude(_) => ValueSort::PositionAltitude,
        ArchivedValue::PositionAltitudeRotation(_) => ValueSort::PositionAltitudeRotation,
        ArchivedValue::Agg(_) => ValueSort::Agg,
        ArchivedValue::Collection(_) => ValueSort::Collection,
        ArchivedValue::EntityFrame(_) => ValueSort::EntityFrame,
        ArchivedValue::EntityFrameSeq(_) => ValueSort::EntityFrameSeq,
    }
}

/// Bytes that lie in `holder`'s as [`Octets`] holding it; copied if they do not.
fn held(holder: &Arc<dyn OctetsHolder>, bytes: &[u8]) -> Octets {
    let base = holder.bytes().as_ptr() as usize;
    (bytes.as_ptr() as usize)
        .checked_sub(base)
        .and_then(|start| Octets::held(Arc::clone(holder), start..start + bytes.len()))
        .unwrap_or_else(|| Octets::from(bytes))
}

/// An archived sequence of little-endian numbers as native ones: the same bytes on a
/// little-endian host, borrowed; converted one by one elsewhere.
fn native_slice<'a, A, N: Clone>(archived: &'a [A], convert: impl Fn(&A) -> N) -> Cow<'a, [N]> {
    #[cfg(target_endian = "little")]
    {
        const { assert!(std::mem::size_of::<A>() == std::mem::size_of::<N>()) };
        const { assert!(std::mem::align_of::<A>() >= std::mem::align_of::<N>()) };
        let _ = &convert;
        // SAFETY: rkyv's little-endian numbers (`i64_le`, `f64_le`) are their native
        // type in a `repr(C)` wrapper of the same size and at least the same alignment
        // (asserted above), and on a little-endian host their bytes are the native
        // value's; any bit pattern is a valid `i64` or `f64`.
        Cow::Borrowed(unsafe {
            std::slice::from_raw_parts(archived.as_ptr().cast::<N>(), archived.len())
        })
    }
    #[cfg(not(target_endian = "little"))]
    {
        Cow::Owned(archived.iter().map(convert).collect())
    }
}

fn vec3(v: &crate::value::ArchivedVec3) -> Vec3 {
    Vec3 { x: v.x.to_native(), y: v.y.to_native(), z: v.z.to_native() }
}

fn position(p: &crate::value::ArchivedPosition) -> Position {
    Position { north: p.north.to_native(), east: p.east.to_native() }
}

fn rotation(r: &crate::value::ArchivedRotation) -> Rotation {
    Rotation { roll: r.roll.to_native(), pitch: r.pitch.to_native(), yaw: r.yaw.to_native() }
}

/// An archived value made owned, octets held in `holder`.
fn owned_value(value: &ArchivedValue, holder: &Arc<dyn OctetsHolder>) -> Value {
    let r = ValueRef::archived(value, holder);
    match value {
        ArchivedValue::NoValue => Value::NoValue,
        ArchivedValue::Long(v) => Value::Long(v.to_native()),
        ArchivedValue::Double(v) => Value::Double(v.to_native()),
        ArchivedValue::Bool(b) => Value::Bool(*b),
        ArchivedValue::String(s) => Value::String(s.as_str().to_owned()),
        ArchivedValue::Time(v) => Value::Time(v.to_native()),
        ArchivedValue::Symbol(s) => Value::Symbol(s.as_str().to_owned()),
        ArchivedValue::OctetSeq(o) => Value::OctetSeq(held(holder, o.as_slice())),
        ArchivedValue::LongSeq(_) => Value::LongSeq(r.as_long_seq().unwrap_or_default().into()),
        ArchivedValue::DoubleSeq(_) => {
            Value::DoubleSeq(r.as_double_seq().unwrap_or_default().into())
        }
        ArchivedValue::SymbolSeq(v) => {
            Value::SymbolSeq(v.iter().map(|s| s.as_str().to_owned()).collect())
        }
        ArchivedValue::Vec(v) => Value::Vec(vec3(v)),
        ArchivedValue::VecSeq(v) => Value::VecSeq(v.iter().map(vec3).collect()),
        ArchivedValue::Pos2(_) => r.as_pos2().map_or(Value::NoValue, Value::Pos2),
        ArchivedValue::Pos2Seq(v) => Value::Pos2Seq(
            v.iter().map(|p| Pos2 { x: p.x.to_native(), y: p.y.to_native() }).collect(),
        ),
        ArchivedValue::Position(p) => Value::Position(position(p)),
        ArchivedValue::Altitude(v) => Value::Altitude(v.to_native()),
        ArchivedValue::Rotation(x) => Value::Rotation(rotation(x)),
        ArchivedValue::PositionAltitude(_) => {
            r.as_position_altitude().map_or(Value::NoValue, Value::PositionAltitude)
        }
        ArchivedValue::PositionAltitudeRotation(_) => {
            r.as_pose().map_or(Value::NoValue, Value::PositionAltitudeRotation)
        }
        ArchivedValue::Agg(v) => Value::Agg(v.iter().map(|x| owned_value(x, holder)).collect()),
        ArchivedValue::Collection(v) => {
            Value::Collection(v.iter().map(|x| owned_value(x, holder)).collect())
        }
        ArchivedValue::EntityFrame(f) => {
            Value::EntityFrame(Box::new(FrameRef::archived(f, holder).to_frame()))
        }
        ArchivedValue::EntityFrameSeq(f) => Value::EntityFrameSeq(
            f.iter().map(|f| FrameRef::archived(f, holder).to_frame()).collect(),
        ),
    }
}
