//! Evaluation of the typed tree over a structure's attributes.
//!
//! Every node returns `Option`: `None` means "undefined" (integer division by zero,
//! integer overflow, or a structure that lacks what its type promised) and propagates
//! up, so the filter as a whole is false. It is never turned into a value halfway:
//! `!(size / 0 == 1)` is false, not true. `&&` and `||` short-circuit from the left,
//! so an undefined right operand that is never evaluated does not count.
//!
//! Nothing here allocates: strings are borrowed from the structure or the filter.

use super::ast::{Arith, Cmp};
use super::typed::{BoolExpr, FloatExpr, IntExpr, StrExpr};
use crate::value::frame::AttributeValuePair;

impl Cmp {
    fn test<T: PartialOrd + ?Sized>(self, a: &T, b: &T) -> bool {
        match self {
            Cmp::Eq => a == b,
            Cmp::Ne => a != b,
            Cmp::Lt => a < b,
            Cmp::Le => a <= b,
            Cmp::Gt => a > b,
            Cmp::Ge => a >= b,
        }
    }
}

impl Arith {
    /// Checked: overflow, division by zero and `i64::MIN / -1` are undefined.
    fn int(self, a: i64, b: i64) -> Option<i64> {
        match self {
            Arith::Add => a.checked_add(b),
            Arith::Sub => a.checked_sub(b),
            Arith::Mul => a.checked_mul(b),
            Arith::Div => a.checked_div(b),
            Arith::Rem => a.checked_rem(b),
        }
    }

    /// IEEE 754: division by zero gives an infinity or NaN, which compare false.
    fn float(self, a: f64, b: f64) -> f64 {
        match self {
            Arith::Add => a + b,
            Arith::Sub => a - b,
            Arith::Mul => a * b,
            Arith::Div => a / b,
            Arith::Rem => a % b,
        }
    }
}

impl BoolExpr {
    pub(super) fn eval(&self, attrs: &[AttributeValuePair]) -> Option<bool> {
        Some(match self {
            BoolExpr::Const(v) => *v,
            BoolExpr::Attr(path) => path.get(attrs)?.as_bool()?,
            BoolExpr::Not(e) => !e.eval(attrs)?,
            BoolExpr::And(a, b) => a.eval(attrs)? && b.eval(attrs)?,
            BoolExpr::Or(a, b) => a.eval(attrs)? || b.eval(attrs)?,
            BoolExpr::Int(cmp, a, b) => cmp.test(&a.eval(attrs)?, &b.eval(attrs)?),
            BoolExpr::Float(cmp, a, b) => cmp.test(&a.eval(attrs)?, &b.eval(attrs)?),
            BoolExpr::Str(cmp, a, b) => cmp.test(a.eval(attrs)?, b.eval(attrs)?),
            BoolExpr::Bool(cmp, a, b) => cmp.test(&a.eval(attrs)?, &b.eval(attrs)?),
        })
    }
}

impl IntExpr {
    fn eval(&self, attrs: &[AttributeValuePair]) -> Option<i64> {
        match self {
            IntExpr::Const(v) => Some(*v),
            IntExpr::Attr(path) => path.get(attrs)?.as_long(),
            IntExpr::Len(path) => path.get(attrs)?.len(),
            IntExpr::Neg(e) => e.eval(attrs)?.checked_neg(),
            IntExpr::Abs(e) => e.eval(attrs)?.checked_abs(),
            IntExpr::Arith(op, a, b) => op.int(a.eval(attrs)?, b.eval(attrs)?),
        }
    }
}

impl FloatExpr {
    fn eval(&self, attrs: &[AttributeValuePair]) -> Option<f64> {
        Some(match self {
            FloatExpr::Const(v) => *v,
            FloatExpr::Attr(path) => path.get(attrs)?.as_double()?,
            FloatExpr::FromInt(e) => e.eval(attrs)? as f64,
            FloatExpr::Neg(e) => -e.eval(attrs)?,
            FloatExpr::Abs(e) => e.eval(attrs)?.abs(),
            FloatExpr::Arith(op, a, b) => op.float(a.eval(attrs)?, b.eval(attrs)?),
        })
    }
}

impl StrExpr {
    fn eval<'a>(&'a self, attrs: &'a [AttributeValuePair]) -> Option<&'a str> {
        match self {
            StrExpr::Const(s) => Some(s),
            StrExpr::Attr(path) => path.get(attrs)?.as_str(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{blob, compile, eval, sample};
    use crate::value::frame::EntityFrame;

    fn all_true(filters: &[&str]) {
        for f in filters {
            assert!(eval(f), "`{f}` should hold");
        }
    }

    fn all_false(filters: &[&str]) {
        for f in filters {
            assert!(!eval(f), "`{f}` should not hold");
        }
    }

    #[test]
    fn integer_arithmetic() {
        all_true(&[
            "size + 1 == 13",
            "size - 20 == -8",
            "size * 2 == 24",
            "size / 5 == 2",
            "size % 5 == 2",
            "x / 2 == -1",
            "x % 2 == -1",
            "-x == 3",
            "- -x == x",
            "abs(x) == 3",
            "abs(size) == size",
            "2 + 3 * 4 == 14",
            "(2 + 3) * 4 == 20",
            "t == 1000 && t > size",
        ]);
        all_false(&["size + 1 == 12", "size / 5 == 3"]);
    }

    #[test]
    fn float_arithmetic_and_promotion() {
        all_true(&[
            "speed * 2 == 5.0",
            "speed + 1 == 3.5",
            "speed - 0.5 == 2",
            "speed / 2 == 1.25",
            "speed % 1 == 0.5",
            "-speed < 0",
            "abs(-speed) == speed",
            "alt > 100 && alt - 0.5 == 119.5",
            "size == 12.0",
            "size > 11.5",
            "size / 5 == 2 && size / 5.0 == 2.4",
            "speed < size",
            "size + speed == 14.5",
            "1e1 == 10",
        ]);
        all_false(&["size < 11.99", "speed > 2.5"]);
    }

    #[test]
    fn every_comparison() {
        all_true(&[
            "size == 12",
            "size != 13",
            "size < 13",
            "size <= 12",
            "size > 11",
            "size >= 12",
        ]);
        all_false(&[
            "size == 13",
            "size != 12",
            "size < 12",
            "size <= 11",
            "size > 12",
            "size >= 13",
        ]);
        all_true(&[
            "speed == 2.5",
            "speed != 2",
            "speed < 3",
            "speed <= 2.5",
            "speed > 2",
            "speed >= 2.5",
        ]);
        all_false(&[
            "speed == 2",
            "speed != 2.5",
            "speed < 2.5",
            "speed <= 2",
            "speed > 3",
            "speed >= 3",
        ]);
    }

    #[test]
    fn string_comparisons() {
        all_true(&[
            r#"name == "blob \"one\"""#,
            r#"sym == "robot1""#,
            r#"sym != "robot2""#,
            r#"sym > "robot0""#,
            r#"sym >= "robot1""#,
            r#"sym < "robot10""#,
            r#"sym <= "s""#,
            r#""a" < "b""#,
            r#""B" < "a""#,
            "name != sym",
            "name <= name",
            r#"empty_name == """#,
            r#""" < "a""#,
        ]);
        all_false(&[r#"sym == "Robot1""#, r#"name < "a""#, r#"empty_name > """#]);
    }

    #[test]
    fn booleans_and_logic() {
        all_true(&[
            "flag",
            "flag == true",
            "flag != false",
            "!flag == false",
            "true && true",
            "true || false",
            "false || true",
            "not false",
            "flag and size > 3 or false",
            "(size > 100) == false",
        ]);
        all_false(&[
            "not flag",
            "true && false",
            "false && true",
            "false || false",
            "!(size > 3)",
            "flag && size > 100",
        ]);
    }

    #[test]
    fn nested_paths() {
        all_true(&[
            "best.size == 40 && best.x == 5",
            "pos.x == 320 && pos.y == 240",
            "vel.x == 1 && vel.y < 0 && vel.z == 0.5",
            "at.north == 10 && at.east == -5",
            "rot.roll < rot.pitch && rot.yaw == 3",
            "pa.altitude == 30 && pa.position.north == 1 && pa.position.east == 2",
            "pose.altitude == 9 && pose.position.east == 8 && pose.position.north == 7",
            "pose.rotation.yaw == -1.5 && pose.rotation.roll == 0 && pose.rotation.pitch == 0",
            "best.size > size && pos.x - best.x > 300",
        ]);
    }

    #[test]
    fn len_of_every_sequence_and_string() {
        all_true(&[
            "len(items) == 2",
            "len(image_data) == 6",
            "len(longs) == 3",
            "len(doubles) == 1",
            "len(syms) == 2",
            "len(vecs) == 0",
            "len(pts) == 4",
            "len(coll) == 2",
            "len(name) == 10",
            "len(sym) == 6",
            "len(empty_name) == 0",
            r#"len("héllo") == 5"#,
            "len(items) * 3 == len(image_data)",
        ]);
    }

    #[test]
    fn division_by_zero_makes_the_filter_false() {
        all_false(&[
            "size / 0 == 0",
            "size / 0 != 0",
            "!(size / 0 == 1)",
            "size % 0 == 0",
            "size / (x + 3) > 0",
            "size / 0 == 1 || true",
            "size != 12 || size % 0 == 1",
        ]);
        // `&&` and `||` short-circuit, so a guard protects the division.
        all_true(&["size == 12 || size / 0 == 1", "x + 3 == 0 || size / (x + 3) > 0 || true"]);
        all_false(&["size != 12 && size / 0 == 1"]);
        // Floats follow IEEE 754 instead.
        all_true(&[
            "speed / 0 > 1000000",
            "-speed / 0.0 < 0",
            "speed / 0 == speed / 0.0",
            "0.0 / 0.0 != 0.0 / 0.0",
        ]);
        all_false(&["0.0 / 0.0 == 0.0 / 0.0", "speed % 0 < 1", "speed % 0 >= 1"]);
    }

    #[test]
    fn integer_overflow_makes_the_filter_false() {
        all_false(&[
            "9223372036854775807 + 1 > 0",
            "9223372036854775807 + 1 <= 0",
            "-9223372036854775808 - 1 < 0",
            "9223372036854775807 * 2 > 0",
            "-9223372036854775808 / -1 > 0",
            "-9223372036854775808 % -1 == 0",
            "abs(-9223372036854775808) > 0",
            "-(-9223372036854775808) > 0",
        ]);
        all_true(&["9223372036854775807 + 1.0 > 0", "-9223372036854775808 < 0"]);
    }

    #[test]
    fn structures_that_break_the_type_do_not_match() {
        let f = compile("best.size > 0").unwrap();
        assert!(f.matches(&sample().attributes));
        let mut s = sample();
        s.set("best", 3i64);
        assert!(!f.matches(&s.attributes));
        s.set("best", EntityFrame::new("b").with("x", 1i64));
        assert!(!f.matches(&s.attributes));
        s.set("best", blob(1, 1));
        assert!(f.matches(&s.attributes));
        assert!(!f.matches(&[]));

        for (filter, attribute, value) in [
            ("pos.x > 0", "pos", crate::Value::Long(1)),
            ("pose.position.north > 0", "pose", crate::Value::Double(1.0)),
            ("len(items) >= 0", "items", crate::Value::Long(1)),
            ("name == name", "name", crate::Value::Long(1)),
            ("flag || true", "flag", crate::Value::NoValue),
            ("speed > 0", "speed", crate::Value::Long(1)),
            ("size > 0", "size", crate::Value::Double(1.0)),
        ] {
            let f = compile(filter).unwrap();
            assert!(f.matches(&sample().attributes), "{filter}");
            let mut s = sample();
            s.set(attribute, value);
            assert!(!f.matches(&s.attributes), "{filter} with a wrong `{attribute}`");
        }
    }
}
