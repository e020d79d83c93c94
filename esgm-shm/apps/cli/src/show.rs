//! How samples and tables look on the terminal and in `--json`.

use esgm_core::value::frame::{AttributeValuePair, EntityFrame};
use esgm_core::{Sample, Value};
use serde_json::{Map, json};

use crate::time_arg::display;

/// A value as JSON; byte sequences (image pixels) as their length, not their bytes.
pub fn value_json(v: &Value) -> serde_json::Value {
    match v {
        Value::NoValue => serde_json::Value::Null,
        Value::Long(v) => json!(v),
        Value::Double(v) => json!(v),
        Value::Bool(v) => json!(v),
        Value::Time(v) => json!(v),
        Value::String(v) | Value::Symbol(v) => json!(v),
        Value::LongSeq(v) => json!(v),
        Value::DoubleSeq(v) => json!(v),
        Value::SymbolSeq(v) => json!(v),
        Value::OctetSeq(o) => json!({ "octets": o.len() }),
        Value::Agg(vs) | Value::Collection(vs) => vs.iter().map(value_json).collect(),
        Value::EntityFrame(f) => frame_json(f),
        Value::EntityFrameSeq(fs) => fs.iter().map(frame_json).collect(),
        other => serde_json::to_value(other).unwrap_or(serde_json::Value::Null),
    }
}

fn attributes_json(attributes: &[AttributeValuePair]) -> serde_json::Value {
    let mut m = Map::new();
    for a in attributes {
        m.insert(a.name.clone(), value_json(&a.value));
    }
    serde_json::Value::Object(m)
}

fn frame_json(f: &EntityFrame) -> serde_json::Value {
    json!({ "name": f.name, "attributes": attributes_json(&f.attributes) })
}

/// A sample as one JSON object.
pub fn sample_json(trajectory: &str, s: &Sample) -> serde_json::Value {
    let mut v = json!({
        "trajectory": trajectory,
        "name": s.structure.name(),
        "valid_time": s.structure.valid_time(),
        "create_time": s.structure.create_time(),
        "add_time": s.add_time,
        // Printed from owned values (an image as its length, never its pixels).
        "attributes": attributes_json(&s.structure.attributes().to_pairs()),
    });
    if let Some(held) = &s.not_interpolated {
        v["not_interpolated"] = json!(held.as_ref());
    }
    if let Some(lineage) = &s.lineage {
        v["lineage"] = json!(lineage.as_ref());
    }
    v
}

/// A sample as one line of text: valid time, entity, attributes, add delay.
pub fn sample_line(s: &Sample) -> String {
    let attrs: Vec<String> = s
        .structure
        .attributes()
        .map(|(name, value)| format!("{name}={}", value_json(&value.to_value())))
        .collect();
    let held = match &s.not_interpolated {
        Some(held) => format!("  (not interpolated, most recent value: {})", held.join(", ")),
        None => String::new(),
    };
    format!(
        "{}  {}  {}  (add delay {:.3} ms){held}",
        display(s.structure.valid_time()),
        s.structure.name(),
        attrs.join(" "),
        s.add_delay() as f64 / 1e6
    )
}

/// Prints a sample in the chosen format.
pub fn print_sample(json: bool, trajectory: &str, s: &Sample) {
    if json {
        println!("{}", sample_json(trajectory, s));
    } else {
        println!("{}", sample_line(s));
    }
}

/// Milliseconds for a table cell: a time in nanoseconds with two decimals, `-` for
/// none. Pads as a string does (`{:>11}`).
pub fn ms(t: Option<i64>) -> Ms {
    Ms(t)
}

/// [`ms`]'s cell, formatted where it is written (a table of 1,000 rows makes no
/// string per cell).
#[derive(Debug, Clone, Copy)]
pub struct Ms(Option<i64>);

impl std::fmt::Display for Ms {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            None => f.pad("-"),
            // Hundredths of a millisecond, rounded half away from zero.
            Some(t) => {
                let (whole, part) = (t / 10_000, t % 10_000);
                let rounded = if part.abs() >= 5_000 { whole + t.signum() } else { whole };
                hundredths(f, i128::from(rounded))
            }
        }
    }
}

/// A number with two decimals for a table cell, padded as a string is (`{:>8}`, not
/// `{:>8.2}`). Made with integer arithmetic: the standard library's exact float
/// formatting costs about 900 instructions a cell, most of `esgm stats`'s printing at
/// 1,000 trajectories.
#[derive(Debug, Clone, Copy)]
pub struct TwoDecimals(pub f64);

impl std::fmt::Display for TwoDecimals {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let scaled = (self.0 * 100.0).round();
        // Beyond what an i128 holds exactly (or not a number): the standard way.
        if !scaled.is_finite() || scaled.abs() >= 9e18 {
            return f.pad(&format!("{:.2}", self.0));
        }
        hundredths(f, scaled as i128)
    }
}

/// Writes `h` hundredths as `units.hh`, padded by `f`'s width and alignment: digits
/// written from the end of a buffer on the stack, with no formatting machinery.
fn hundredths(f: &mut std::fmt::Formatter<'_>, h: i128) -> std::fmt::Result {
    // Every caller's value fits in 64 bits; the standard way otherwise.
    let Ok(mut rest) = u64::try_from(h.unsigned_abs()) else {
        return f.pad(&format!("{}.{:02}", h / 100, h.unsigned_abs() % 100));
    };
    let mut buf = [0u8; 48];
    let mut at = buf.len();
    let mut push = |byte: u8| {
        at -= 1;
        buf[at] = byte;
    };
    for _ in 0..2 {
        push(b'0' + (rest % 10) as u8);
        rest /= 10;
    }
    push(b'.');
    loop {
        push(b'0' + (rest % 10) as u8);
        rest /= 10;
        if rest == 0 {
            break;
        }
    }
    if h < 0 {
        push(b'-');
    }
    f.pad(std::str::from_utf8(&buf[at..]).map_err(|_| std::fmt::Error)?)
}

/// One line of a table, made cell by cell in one string with the padding written by
/// hand: the standard width formatting writes a fill character per call, most of the
/// time of a table of 1,000 rows.
#[derive(Debug, Default)]
pub struct Line {
    text: String,
    cell: String,
}

impl Line {
    /// Starts a new line (the buffers are kept).
    pub fn clear(&mut self) -> &mut Self {
        self.text.clear();
        self
    }

    /// Adds `value` left-aligned in `width` characters, after a space unless first.
    pub fn left(&mut self, value: impl std::fmt::Display, width: usize) -> &mut Self {
        self.cell(value);
        self.text.push_str(&self.cell);
        self.pad(width);
        self
    }

    /// Adds `value` right-aligned in `width` characters, after a space unless first.
    pub fn right(&mut self, value: impl std::fmt::Display, width: usize) -> &mut Self {
        self.cell(value);
        self.pad(width);
        self.text.push_str(&self.cell);
        self
    }

    /// The line so far.
    pub fn as_str(&self) -> &str {
        &self.text
    }

    fn cell(&mut self, value: impl std::fmt::Display) {
        use std::fmt::Write as _;
        if !self.text.is_empty() {
            self.text.push(' ');
        }
        self.cell.clear();
        // Writing to a string cannot fail.
        let _infallible = write!(self.cell, "{value}");
    }

    fn pad(&mut self, width: usize) {
        const SPACES: &str = "                                ";
        let mut missing = width.saturating_sub(self.cell.chars().count());
        while missing > 0 {
            let n = missing.min(SPACES.len());
            self.text.push_str(&SPACES[..n]);
            missing -= n;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{TwoDecimals, ms};

    #[test]
    fn cells_read_as_the_standard_formatting_would() {
        for x in [0.0, 1.0, 12.345_678, 39556.96, 0.004, 0.006, 99.999, -3.25, 1e12] {
            assert_eq!(format!("{:>10}", TwoDecimals(x)), format!("{x:>10.2}"), "{x}");
        }
        assert_eq!(format!("{}", TwoDecimals(f64::NAN)), "NaN");
        for t in [0_i64, 1, 4_999, 5_000, 3_607_772_530_123, -2_500_000, i64::MAX, i64::MIN] {
            let standard = format!("{:>11.2}", t as f64 / 1e6);
            assert_eq!(format!("{:>11}", ms(Some(t))), standard, "{t}");
        }
        assert_eq!(format!("{:>3}", ms(None)), "  -");
    }

    #[test]
    fn a_line_pads_as_width_formatting_does() {
        let mut line = super::Line::default();
        line.clear().left("t1", 20).left("primitive", 10).right(5, 7).right(TwoDecimals(2.5), 8);
        assert_eq!(
            line.as_str(),
            format!("{:<20} {:<10} {:>7} {:>8.2}", "t1", "primitive", 5, 2.5)
        );
        let long = "a_name_longer_than_its_column_of_twenty";
        line.clear().left(long, 20).right(ms(None), 11).left("ü", 3);
        assert_eq!(line.as_str(), format!("{long:<20} {:>11} {:<3}", "-", "ü"));
    }
}
