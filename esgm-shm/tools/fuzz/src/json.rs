//! Mutations of JSON that keep it JSON: a value somewhere in the tree replaced by a
//! boundary value, by a value from another input, removed, repeated or wrapped. Most
//! results still decode as a protocol message, with hostile contents: names empty,
//! long, with `/`; numbers at their limits; lists of thousands; types swapped.

use serde_json::{Map, Number, Value};

use crate::rng::Rng;

/// JSON's own tokens, which a text mutation of any JSON protocol splices in: its
/// punctuation and words, numbers at their limits and escapes that are not text.
const JSON_TOKENS: [&str; 19] = [
    "{",
    "}",
    "[",
    "]",
    "\"",
    ":",
    ",",
    "null",
    "true",
    "false",
    "18446744073709551615",
    "9223372036854775807",
    "-1",
    "-0.0",
    "1e999",
    "\\",
    "\"\\u0000\"",
    "\"\\ud800\"",
    "\"\\uDBFF\\uDFFF\"",
];

/// The tokens a target's text mutations splice: JSON's own and `words`, the
/// protocol's (its variant names, fields and values that matter to it).
pub fn json_tokens(words: &[&'static str]) -> Vec<&'static str> {
    JSON_TOKENS.iter().chain(words).copied().collect()
}

/// Applies one or two tree mutations to the JSON in `data`; `None` if it is not JSON.
pub fn mutate_json(rng: &mut Rng, data: &[u8], others: &[Vec<u8>]) -> Option<Vec<u8>> {
    let mut tree: Value = serde_json::from_slice(data).ok()?;
    for _ in 0..1 + rng.below(3) / 2 {
        let n = count(&tree);
        let target = rng.below(n);
        let donor = rng.pick(others);
        let donor: Option<Value> = serde_json::from_slice(donor).ok();
        let mut k = target;
        visit(&mut tree, &mut k, rng, donor.as_ref());
    }
    serde_json::to_vec(&tree).ok()
}

/// The most bytes one repetition adds: a request is cut at the coordinator's limit
/// anyway, and the fuzzer's own memory must stay small.
const MAX_GROWTH: usize = 1 << 20;

/// A value's encoded size (at least 1).
fn size(v: &Value) -> usize {
    serde_json::to_vec(v).map_or(1, |b| b.len().max(1))
}

fn count(v: &Value) -> usize {
    1 + match v {
        Value::Array(a) => a.iter().map(count).sum(),
        Value::Object(o) => o.values().map(count).sum(),
        _ => 0,
    }
}

/// Walks to the `k`-th node (pre-order) and mutates it.
fn visit(v: &mut Value, k: &mut usize, rng: &mut Rng, donor: Option<&Value>) -> bool {
    if *k == 0 {
        mutate_node(v, rng, donor);
        return true;
    }
    *k -= 1;
    match v {
        Value::Array(a) => a.iter_mut().any(|c| visit(c, k, rng, donor)),
        Value::Object(o) => o.values_mut().any(|c| visit(c, k, rng, donor)),
        _ => false,
    }
}

/// Any node of `v`, at random.
fn some_node<'a>(v: &'a Value, rng: &mut Rng) -> &'a Value {
    let mut k = rng.below(count(v));
    fn walk<'a>(v: &'a Value, k: &mut usize) -> Option<&'a Value> {
        if *k == 0 {
            return Some(v);
        }
        *k -= 1;
        match v {
            Value::Array(a) => a.iter().find_map(|c| walk(c, k)),
            Value::Object(o) => o.values().find_map(|c| walk(c, k)),
            _ => None,
        }
    }
    walk(v, &mut k).unwrap_or(v)
}

const STRINGS: [&str; 10] = [
    "",
    " ",
    "a/b",
    "..",
    "\u{0}",
    "\u{202e}evil",
    "name with spaces",
    "ünïcødé",
    "robot_state",
    "Image",
];

fn boundary(rng: &mut Rng) -> Value {
    match rng.below(8) {
        0 => Value::Null,
        1 => Value::Bool(rng.chance(50)),
        2 => Value::from(*rng.pick(&[0i64, -1, 1, i64::MIN, i64::MAX, i64::from(u32::MAX)])),
        3 => Value::from(*rng.pick(&[u64::MAX, 1 << 53, 1 << 63])),
        4 => Number::from_f64(*rng.pick(&[-0.0, 0.5, 1e300, -1e300, f64::MIN_POSITIVE]))
            .map_or(Value::Null, Value::Number),
        5 => Value::from(*rng.pick(&STRINGS)),
        6 => Value::from("x".repeat(*rng.pick(&[100usize, 101, 255, 256, 4096, 100_000]))),
        _ => Value::Object(Map::new()),
    }
}

/// A value of the same JSON type as `v` (so the message most likely still decodes)
/// at a boundary: a string empty, long or hostile; a number at a limit; a list
/// emptied, shortened or repeated thousands of times.
fn same_type(v: &mut Value, rng: &mut Rng) {
    match v {
        Value::String(s) => {
            *s = match rng.below(4) {
                0 => rng.pick(&STRINGS).to_string(),
                1 => "x".repeat(*rng.pick(&[100usize, 101, 255, 256, 4096, 100_000])),
                2 => format!("{s}{}", rng.pick(&STRINGS)),
                _ => s.repeat(2),
            }
        }
        Value::Number(n) => {
            *v = if n.is_f64() {
                Number::from_f64(*rng.pick(&[-0.0, 0.5, 1e300, -1e300, f64::MIN_POSITIVE]))
                    .map_or(Value::Null, Value::Number)
            } else if rng.chance(50) {
                Value::from(*rng.pick(&[0i64, -1, 1, i64::MIN, i64::MAX, i64::from(u32::MAX)]))
            } else {
                Value::from(*rng.pick(&[u64::MAX, 1 << 53, 1 << 63, u64::from(u32::MAX) + 1]))
            }
        }
        Value::Bool(b) => *b = !*b,
        Value::Array(a) if !a.is_empty() => match rng.below(3) {
            0 => a.clear(),
            1 => {
                let i = rng.below(a.len());
                a.remove(i);
            }
            _ => {
                let item = a[rng.below(a.len())].clone();
                let n = *rng.pick(&[1usize, 10, 1000, 10_000]).min(&(MAX_GROWTH / size(&item)));
                a.extend(std::iter::repeat_n(item, n));
            }
        },
        _ => *v = boundary(rng),
    }
}

fn mutate_node(v: &mut Value, rng: &mut Rng, donor: Option<&Value>) {
    match rng.below(10) {
        0..=5 => same_type(v, rng),
        6 => *v = boundary(rng),
        7 => {
            if let Some(d) = donor {
                *v = some_node(d, rng).clone();
            }
        }
        8 => match v {
            Value::Object(o) if !o.is_empty() => {
                let key = o.keys().nth(rng.below(o.len())).cloned().unwrap_or_default();
                o.remove(&key);
            }
            Value::Object(o) => {
                o.insert(rng.pick(&STRINGS).to_string(), boundary(rng));
            }
            _ => *v = Value::Array(vec![v.clone(); 2]),
        },
        _ => {
            // The same value, nested a few levels deeper.
            for _ in 0..1 + rng.below(4) {
                *v = if rng.chance(50) {
                    Value::Array(vec![v.take()])
                } else {
                    let mut o = Map::new();
                    o.insert("Type".into(), v.take());
                    Value::Object(o)
                };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutated_json_stays_json_and_changes() {
        let seed =
            br#"{"CreateTrajectory":{"spec":{"name":"a","inputs":[1,2]},"host":"h"}}"#.to_vec();
        let mut changed = 0;
        for i in 0..500 {
            let out = mutate_json(&mut Rng::for_case(1, i), &seed, std::slice::from_ref(&seed));
            let out = out.unwrap_or_else(|| panic!("case {i}"));
            assert!(serde_json::from_slice::<Value>(&out).is_ok());
            changed += usize::from(out != seed);
        }
        assert!(changed > 400, "{changed} of 500 changed");
    }
}
