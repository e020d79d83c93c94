//! Mutations of text (JSON requests, TOML files): tokens of the format inserted,
//! numbers replaced by boundary numbers, lines duplicated, dropped and swapped, deep
//! nesting and long strings; byte mutations ([`crate::mutate`]) now and then, so
//! invalid UTF-8 and broken escapes are tried too.

use crate::mutate;
use crate::rng::Rng;

const NUMBERS: [&str; 16] = [
    "0",
    "-1",
    "-0",
    "1e400",
    "-1e400",
    "1.5e-400",
    "9223372036854775807",
    "9223372036854775808",
    "-9223372036854775809",
    "18446744073709551616",
    "4294967296",
    "0x7fffffff",
    "nan",
    "inf",
    "1979-05-27T07:32:00Z",
    "99999999999999999999999999999999",
];

/// Applies one to six random text mutations to `data`; `tokens` are the format's
/// words and punctuation, `others` inputs to splice lines from.
pub fn mutate_text(rng: &mut Rng, data: &mut Vec<u8>, others: &[Vec<u8>], tokens: &[&str]) {
    for _ in 0..1 + rng.below(6) {
        mutate_text_once(rng, data, others, tokens);
    }
    data.truncate(mutate::MAX_LEN);
}

fn line_starts(data: &[u8]) -> Vec<usize> {
    std::iter::once(0)
        .chain(data.iter().enumerate().filter(|(_, b)| **b == b'\n').map(|(i, _)| i + 1))
        .collect()
}

/// A random line of `data` as a byte range (its newline included).
fn some_line(rng: &mut Rng, data: &[u8]) -> std::ops::Range<usize> {
    let starts = line_starts(data);
    let i = rng.below(starts.len());
    let end = starts.get(i + 1).copied().unwrap_or(data.len());
    starts[i]..end
}

fn mutate_text_once(rng: &mut Rng, data: &mut Vec<u8>, others: &[Vec<u8>], tokens: &[&str]) {
    let at = rng.below(data.len() + 1);
    match rng.below(10) {
        0 | 1 => {
            let token = rng.pick(tokens).as_bytes().to_vec();
            data.splice(at..at, token);
        }
        2 => {
            // A number (a run of digits) replaced by a boundary number.
            let start = (at..data.len()).find(|i| data[*i].is_ascii_digit());
            if let Some(start) = start {
                let end =
                    (start..data.len()).find(|i| !data[*i].is_ascii_digit()).unwrap_or(data.len());
                let n = rng.pick(&NUMBERS).as_bytes().to_vec();
                data.splice(start..end, n);
            }
        }
        3 => {
            let line = some_line(rng, data);
            let copy = data[line.clone()].to_vec();
            let to = *rng.pick(&line_starts(data));
            data.splice(to..to, copy);
        }
        4 => {
            let line = some_line(rng, data);
            data.drain(line);
        }
        5 if !others.is_empty() => {
            let other = rng.pick(others);
            let line = some_line(rng, other);
            let to = *rng.pick(&line_starts(data));
            data.splice(to..to, other[line].to_vec());
        }
        6 => {
            // Deep nesting: an opener repeated, closed or not.
            let (open, close) =
                *rng.pick(&[("[", "]"), ("{\"a\":", "}"), ("{a=", "}"), ("[[", "]]")]);
            let depth = *rng.pick(&[8usize, 63, 64, 65, 127, 128, 129, 1000, 100_000]);
            let mut nest = open.repeat(depth);
            if rng.chance(50) {
                nest.push_str(&close.repeat(depth));
            }
            data.splice(at..at, nest.into_bytes());
        }
        7 => {
            // A long string (a name of kilobytes or more).
            let n = *rng.pick(&[101usize, 256, 4096, 65_536, 200_000]);
            let c = *rng.pick(&[b'x', b'/', b' ', b'\\', b'"', 0xc3]);
            data.splice(at..at, std::iter::repeat_n(c, n));
        }
        _ => mutate::mutate_once(rng, data, others),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_mutations_change_text() {
        let seed = b"[[trajectory]]\nname = \"a\"\ncache = 10\n".to_vec();
        let mut changed = 0;
        for i in 0..1_000 {
            let mut data = seed.clone();
            mutate_text(&mut Rng::for_case(1, i), &mut data, std::slice::from_ref(&seed), &["="]);
            changed += usize::from(data != seed);
        }
        assert!(changed > 900, "only {changed} of 1000 mutated");
    }
}
