//! Fluent generators in a configuration file and on the command line (G1, G4, E6):
//! `generate = ["robot_state:linear", "altitude:most-recent:median"]`, each entry a
//! trajectory with the generator's approximation and merge rules,
//! `TRAJ[:APPROXIMATION[:MERGE]]`. One entry samples the generator's values, several
//! sample their state (`state(s1..sn)`), and `function = UNIT` samples that unit's
//! temporal function of them (`compute_at`), every `period`.

use anyhow::bail;
use esgm_core::approximation::{MergeRule, ValueApproximation};
use esgm_core::generator::GeneratorPolicy;
use esgm_core::type_registry::closest_name;

/// The approximation rules by the words a file uses (the seed's
/// `ValueApproximationConstraint`; `default` needs attribute values, so only Rust can
/// give it).
const APPROXIMATIONS: [(&str, ValueApproximation); 5] = [
    ("none", ValueApproximation::None),
    ("closest", ValueApproximation::Closest),
    ("most-recent", ValueApproximation::MostRecent),
    ("linear", ValueApproximation::Linear),
    ("linear-strict", ValueApproximation::LinearStrict),
];

/// The merge rules by the words a file uses (the seed's merge constraint).
const MERGES: [(&str, MergeRule); 4] = [
    ("keep-first", MergeRule::KeepFirst),
    ("keep-last", MergeRule::KeepLast),
    ("average", MergeRule::Average),
    ("median", MergeRule::Median),
];

/// One `TRAJ[:APPROXIMATION[:MERGE]]` entry: the trajectory and its generator policy.
/// Left out, the approximation is `most-recent` (a generator is a total function, so
/// `none` is rarely what a sampled stream wants) and the merge `keep-last`.
pub fn parse_generator(entry: &str) -> anyhow::Result<(String, GeneratorPolicy)> {
    let mut parts = entry.split(':');
    let trajectory = parts.next().unwrap_or_default().trim();
    if trajectory.is_empty() {
        bail!("generator `{entry}`: expected TRAJECTORY[:APPROXIMATION[:MERGE]]");
    }
    let approximation = match parts.next() {
        None => ValueApproximation::MostRecent,
        Some(word) => rule(entry, "approximation", word, &APPROXIMATIONS)?,
    };
    let merge = match parts.next() {
        None => MergeRule::KeepLast,
        Some(word) => rule(entry, "merge", word, &MERGES)?,
    };
    if let Some(extra) = parts.next() {
        bail!(
            "generator `{entry}`: unexpected `:{extra}`; expected TRAJECTORY[:APPROXIMATION[:MERGE]]"
        );
    }
    Ok((trajectory.to_owned(), GeneratorPolicy { approximation, merge }))
}

fn rule<T: Clone>(entry: &str, what: &str, word: &str, rules: &[(&str, T)]) -> anyhow::Result<T> {
    let word = word.trim();
    if let Some((_, r)) = rules.iter().find(|(w, _)| *w == word) {
        return Ok(r.clone());
    }
    let names: Vec<&str> = rules.iter().map(|(w, _)| *w).collect();
    let hint = closest_name(word, names.iter().copied())
        .map(|s| format!("did you mean `{s}`? "))
        .unwrap_or_default();
    bail!("generator `{entry}`: unknown {what} `{word}`; {hint}one of {}", names.join(", "))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn entries_with_their_defaults() {
        let (t, g) = parse_generator("robot_state").unwrap();
        assert_eq!(t, "robot_state");
        assert_eq!(g.approximation, ValueApproximation::MostRecent);
        assert_eq!(g.merge, MergeRule::KeepLast);
        let (_, g) = parse_generator("alt:linear:median").unwrap();
        assert_eq!((g.approximation, g.merge), (ValueApproximation::Linear, MergeRule::Median));
    }

    #[test]
    fn bad_entries_name_what_is_wrong() {
        let e = parse_generator("alt:lineer").unwrap_err().to_string();
        assert!(e.contains("unknown approximation `lineer`") && e.contains("`linear`"), "{e}");
        let e = parse_generator("alt:linear:mean").unwrap_err().to_string();
        assert!(e.contains("unknown merge `mean`") && e.contains("median"), "{e}");
        assert!(parse_generator(":linear").is_err());
        assert!(parse_generator("alt:linear:median:x").unwrap_err().to_string().contains(":x"));
    }
}
