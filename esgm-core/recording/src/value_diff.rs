//! Comparing two structures attribute by attribute: where they first differ, and how
//! far apart their numbers are.
//!
//! Every leaf is compared and named by its path (`position.north`, `blobs[2].x`,
//! `image_data[1043]`), so a report can say *which* number differs, not only that two
//! structures do. Numbers (integers, floats, times, and the components of the
//! geometric tuples) are equal when bitwise equal, or, with a tolerance, when
//! `|a − b| ≤ tolerance`; everything else is equal when equal. Octet sequences
//! (images) are compared byte for byte and the first differing byte is named.

use esgm_core::value::frame::{AttributeValuePair, EntityStructure};
use esgm_core::value::{Pos2, Position, Rotation, Value, Vec3};

/// One place where two values differ.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LeafDifference {
    /// The attribute path.
    pub attribute: String,
    /// The first value, as text.
    pub a: String,
    /// The second value, as text.
    pub b: String,
}

/// The largest numeric distance between two values.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LeafDeviation {
    /// The attribute path.
    pub attribute: String,
    /// `|a − b|`.
    pub deviation: f64,
    /// The first value, as text.
    pub a: String,
    /// The second value, as text.
    pub b: String,
}

/// How two structures compare.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct StructureDiff {
    /// The first difference, in attribute order (none: equal).
    pub first: Option<LeafDifference>,
    /// How many leaves differ.
    pub differing_leaves: u64,
    /// The largest numeric deviation over every numeric leaf (also those within the
    /// tolerance); none if no numeric leaf deviates.
    pub largest: Option<LeafDeviation>,
}

impl StructureDiff {
    /// True if the structures are equal (within the tolerance).
    pub fn is_equal(&self) -> bool {
        self.first.is_none()
    }
}

/// Compares `a` and `b`: name, optionally create time, and every attribute (those of
/// `a` in order, then any only `b` has). `tolerance` applies to numeric leaves; `None`
/// asks for bitwise equality. Valid times are the caller's (it aligned on them).
pub fn diff_structures(
    a: &EntityStructure,
    b: &EntityStructure,
    tolerance: Option<f64>,
    create_time: bool,
) -> StructureDiff {
    let mut w = Walker { tolerance, out: StructureDiff::default() };
    if a.name != b.name {
        w.differ("(name)", format!("{:?}", a.name), format!("{:?}", b.name));
    }
    if create_time && a.create_time != b.create_time {
        w.differ("(create_time)", a.create_time.to_string(), b.create_time.to_string());
    }
    w.attributes("", &a.attributes, &b.attributes);
    w.out
}

struct Walker {
    tolerance: Option<f64>,
    out: StructureDiff,
}

fn join(path: &str, name: &str) -> String {
    if path.is_empty() { name.to_owned() } else { format!("{path}.{name}") }
}

/// A value for people, cut short when long.
pub fn value_text(v: &Value) -> String {
    let s = match v {
        Value::Double(x) | Value::Altitude(x) => x.to_string(),
        Value::Long(x) | Value::Time(x) => x.to_string(),
        Value::Bool(x) => x.to_string(),
        Value::String(s) | Value::Symbol(s) => format!("{s:?}"),
        Value::OctetSeq(o) => format!("{} bytes", o.len()),
        Value::NoValue => "no value".to_owned(),
        other => format!("{other:?}"),
    };
    const MAX: usize = 120;
    if s.len() > MAX {
        let mut end = MAX;
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        format!("{}…", &s[..end])
    } else {
        s
    }
}

impl Walker {
    fn differ(&mut self, path: &str, a: String, b: String) {
        self.out.differing_leaves += 1;
        if self.out.first.is_none() {
            self.out.first = Some(LeafDifference { attribute: path.to_owned(), a, b });
        }
    }

    fn deviation(&mut self, path: &str, d: f64, a: String, b: String) {
        if d > 0.0 && self.out.largest.as_ref().is_none_or(|l| d > l.deviation) {
            self.out.largest =
                Some(LeafDeviation { attribute: path.to_owned(), deviation: d, a, b });
        }
    }

    fn float(&mut self, path: &str, a: f64, b: f64) {
        let bitwise = a.to_bits() == b.to_bits();
        let d = (a - b).abs();
        if d.is_finite() {
            self.deviation(path, d, a.to_string(), b.to_string());
        }
        let equal = bitwise || self.tolerance.is_some_and(|t| d <= t);
        if !equal {
            self.differ(path, a.to_string(), b.to_string());
        }
    }

    fn int(&mut self, path: &str, a: i64, b: i64) {
        // In i128: the distance between extreme i64s overflows i64.
        let d = (i128::from(a) - i128::from(b)).unsigned_abs() as f64;
        self.deviation(path, d, a.to_string(), b.to_string());
        let equal = a == b || self.tolerance.is_some_and(|t| d <= t);
        if !equal {
            self.differ(path, a.to_string(), b.to_string());
        }
    }

    fn floats(&mut self, path: &str, pairs: &[(&str, f64, f64)]) {
        for (name, a, b) in pairs {
            self.float(&join(path, name), *a, *b);
        }
    }

    fn vec3(&mut self, path: &str, a: &Vec3, b: &Vec3) {
        self.floats(path, &[("x", a.x, b.x), ("y", a.y, b.y), ("z", a.z, b.z)]);
    }

    fn pos2(&mut self, path: &str, a: &Pos2, b: &Pos2) {
        self.floats(path, &[("x", a.x, b.x), ("y", a.y, b.y)]);
    }

    fn position(&mut self, path: &str, a: &Position, b: &Position) {
        self.floats(path, &[("north", a.north, b.north), ("east", a.east, b.east)]);
    }

    fn rotation(&mut self, path: &str, a: &Rotation, b: &Rotation) {
        self.floats(
            path,
            &[("roll", a.roll, b.roll), ("pitch", a.pitch, b.pitch), ("yaw", a.yaw, b.yaw)],
        );
    }

    /// Element-wise over two sequences: a length difference first, then the common
    /// prefix.
    fn seq<T>(
        &mut self,
        path: &str,
        a: &[T],
        b: &[T],
        mut each: impl FnMut(&mut Self, &str, &T, &T),
    ) {
        if a.len() != b.len() {
            self.differ(&format!("{path}.len"), a.len().to_string(), b.len().to_string());
        }
        for (i, (x, y)) in a.iter().zip(b).enumerate() {
            each(self, &format!("{path}[{i}]"), x, y);
        }
    }

    fn attributes(&mut self, path: &str, a: &[AttributeValuePair], b: &[AttributeValuePair]) {
        for pa in a {
            let p = join(path, &pa.name);
            match b.iter().find(|pb| pb.name == pa.name) {
                Some(pb) => self.value(&p, &pa.value, &pb.value),
                None => self.differ(&p, value_text(&pa.value), "(missing)".into()),
            }
        }
        for pb in b.iter().filter(|pb| !a.iter().any(|pa| pa.name == pb.name)) {
            self.differ(&join(path, &pb.name), "(missing)".into(), value_text(&pb.value));
        }
    }

    fn value(&mut self, path: &str, a: &Value, b: &Value) {
        match (a, b) {
            (Value::Double(x), Value::Double(y)) | (Value::Altitude(x), Value::Altitude(y)) => {
                self.float(path, *x, *y);
            }
            (Value::Long(x), Value::Long(y)) | (Value::Time(x), Value::Time(y)) => {
                self.int(path, *x, *y)
            }
            (Value::Vec(x), Value::Vec(y)) => self.vec3(path, x, y),
            (Value::Pos2(x), Value::Pos2(y)) => self.pos2(path, x, y),
            (Value::Position(x), Value::Position(y)) => self.position(path, x, y),
            (Value::Rotation(x), Value::Rotation(y)) => self.rotation(path, x, y),
            (Value::PositionAltitude(x), Value::PositionAltitude(y)) => {
                self.position(&join(path, "position"), &x.position, &y.position);
                self.float(&join(path, "altitude"), x.altitude, y.altitude);
            }
            (Value::PositionAltitudeRotation(x), Value::PositionAltitudeRotation(y)) => {
                self.position(&join(path, "position"), &x.position, &y.position);
                self.float(&join(path, "altitude"), x.altitude, y.altitude);
                self.rotation(&join(path, "rotation"), &x.rotation, &y.rotation);
            }
            (Value::LongSeq(x), Value::LongSeq(y)) => {
                self.seq(path, x, y, |w, p, a, b| w.int(p, *a, *b))
            }
            (Value::DoubleSeq(x), Value::DoubleSeq(y)) => {
                self.seq(path, x, y, |w, p, a, b| w.float(p, *a, *b))
            }
            (Value::VecSeq(x), Value::VecSeq(y)) => {
                self.seq(path, x, y, |w, p, a, b| w.vec3(p, a, b))
            }
            (Value::Pos2Seq(x), Value::Pos2Seq(y)) => {
                self.seq(path, x, y, |w, p, a, b| w.pos2(p, a, b))
            }
            (Value::SymbolSeq(x), Value::SymbolSeq(y)) => self.seq(path, x, y, |w, p, a, b| {
                if a != b {
                    w.differ(p, format!("{a:?}"), format!("{b:?}"));
                }
            }),
            (Value::Agg(x), Value::Agg(y)) | (Value::Collection(x), Value::Collection(y)) => {
                self.seq(path, x, y, |w, p, a, b| w.value(p, a, b));
            }
            (Value::EntityFrame(x), Value::EntityFrame(y)) => {
                if x.name != y.name {
                    self.differ(
                        &join(path, "(name)"),
                        format!("{:?}", x.name),
                        format!("{:?}", y.name),
                    );
                }
                self.attributes(path, &x.attributes, &y.attributes);
            }
            (Value::EntityFrameSeq(x), Value::EntityFrameSeq(y)) => {
                self.seq(path, x, y, |w, p, a, b| {
                    if a.name != b.name {
                        w.differ(
                            &join(p, "(name)"),
                            format!("{:?}", a.name),
                            format!("{:?}", b.name),
                        );
                    }
                    w.attributes(p, &a.attributes, &b.attributes);
                })
            }
            (Value::OctetSeq(x), Value::OctetSeq(y)) => {
                let (x, y): (&[u8], &[u8]) = (x, y);
                if let Some(i) = x.iter().zip(y).position(|(p, q)| p != q) {
                    self.differ(
                        &format!("{path}[{i}]"),
                        format!("{:#04x}", x[i]),
                        format!("{:#04x}", y[i]),
                    );
                } else if x.len() != y.len() {
                    self.differ(&format!("{path}.len"), x.len().to_string(), y.len().to_string());
                }
            }
            (x, y) => {
                if x != y {
                    self.differ(path, value_text(x), value_text(y));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use esgm_core::EntityFrame;
    use esgm_core::octets::Octets;

    fn es() -> EntityStructure {
        EntityStructure::new("r", 5, 6)
            .with("x", 1.0)
            .with("n", 3_i64)
            .with("blobs", Value::EntityFrameSeq(vec![EntityFrame::new("b").with("size", 2.0)]))
            .with("image_data", Octets::new(vec![1, 2, 3]))
    }

    #[test]
    fn equal_structures_have_no_difference() {
        let d = diff_structures(&es(), &es(), None, true);
        assert!(d.is_equal(), "{d:?}");
        assert_eq!(d.largest, None);
    }

    #[test]
    fn names_nested_paths_bytes_and_the_largest_deviation() {
        let mut b = es();
        b.set("blobs", Value::EntityFrameSeq(vec![EntityFrame::new("b").with("size", 2.5)]));
        b.set("image_data", Octets::new(vec![1, 9, 3]));
        b.set("n", 10_i64);
        let d = diff_structures(&es(), &b, None, true);
        let first = d.first.clone().expect("differs");
        assert_eq!(
            (first.attribute.as_str(), first.a.as_str(), first.b.as_str()),
            ("n", "3", "10")
        );
        assert_eq!(d.differing_leaves, 3);
        let largest = d.largest.expect("numeric deviation");
        assert_eq!((largest.attribute.as_str(), largest.deviation), ("n", 7.0));
        b.set("n", 3_i64);
        let d = diff_structures(&es(), &b, None, true);
        assert_eq!(d.first.expect("differs").attribute, "blobs[0].size");
        b.set("blobs", es().get("blobs").cloned().unwrap_or_default());
        let d = diff_structures(&es(), &b, None, true);
        let first = d.first.expect("differs");
        assert_eq!(
            (first.attribute.as_str(), first.a.as_str(), first.b.as_str()),
            ("image_data[1]", "0x02", "0x09")
        );
    }

    #[test]
    fn a_tolerance_applies_to_numbers_only() {
        let b = es().with("x", 1.0 + 1e-9);
        assert!(!diff_structures(&es(), &b, None, true).is_equal(), "bitwise by default");
        assert!(diff_structures(&es(), &b, Some(1e-6), true).is_equal());
        let c = es().with("image_data", Octets::new(vec![1, 2, 4]));
        assert!(!diff_structures(&es(), &c, Some(100.0), true).is_equal(), "bytes are exact");
    }
}
