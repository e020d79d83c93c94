//! Fluent generators written as words (G1, G4, E6): `robot_state:linear`,
//! `altitude:most-recent:median`, each a trajectory with the generator's approximation
//! and merge rules, `TRAJ[:APPROXIMATION[:MERGE]]`. One grammar for every face that
//! takes them: a system file's `generate = [...]`, `esgm traj create --generate` and
//! the Python package.

use crate::approximation::{MergeRule, ValueApproximation};
use crate::generator::GeneratorPolicy;
use crate::type_registry::closest_name;

/// The approximation rules by their words (the seed's `ValueApproximationConstraint`;
/// `default` needs attribute values, so it has no word).
pub const APPROXIMATIONS: [(&str, ValueApproximation); 5] = [
    ("none", ValueApproximation::None),
    ("closest", ValueApproximation::Closest),
    ("most-recent", ValueApproximation::MostRecent),
    ("linear", ValueApproximation::Linear),
    ("linear-strict", ValueApproximation::LinearStrict),
];

/// The merge rules by their words (the seed's merge constraint).
pub const MERGES: [(&str, MergeRule); 4] = [
    ("keep-first", MergeRule::KeepFirst),
    ("keep-last", MergeRule::KeepLast),
    ("average", MergeRule::Average),
    ("median", MergeRule::Median),
];

/// A generator entry that is not `TRAJ[:APPROXIMATION[:MERGE]]`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum GeneratorEntryError {
    /// No trajectory before the first `:`.
    #[error("generator `{entry}`: expected TRAJECTORY[:APPROXIMATION[:MERGE]]")]
    NoTrajectory {
        /// The entry as written.
        entry: String,
    },
    /// A rule word that is not one of its kind's.
    #[error("generator `{entry}`: unknown {rule} `{word}`; {hint}one of {known}")]
    UnknownRule {
        /// The entry as written.
        entry: String,
        /// `approximation` or `merge`.
        rule: &'static str,
        /// The word.
        word: String,
        /// `did you mean `x`? `, or nothing.
        hint: String,
        /// Every word of that kind, comma-separated.
        known: String,
    },
    /// Something after the merge rule.
    #[error(
        "generator `{entry}`: unexpected `:{extra}`; expected TRAJECTORY[:APPROXIMATION[:MERGE]]"
    )]
    Extra {
        /// The entry as written.
        entry: String,
        /// What followed.
        extra: String,
    },
}

/// One `TRAJ[:APPROXIMATION[:MERGE]]` entry: the trajectory and its generator policy.
/// Left out, the approximation is `most-recent` (a generator is a total function, so
/// `none` is rarely what a sampled stream wants) and the merge `keep-last`.
///
/// # Errors
/// [`GeneratorEntryError`], naming the entry and what is wrong in it.
pub fn parse_generator(entry: &str) -> Result<(String, GeneratorPolicy), GeneratorEntryError> {
    let mut parts = entry.split(':');
    let trajectory = parts.next().unwrap_or_default().trim();
    if trajectory.is_empty() {
        return Err(GeneratorEntryError::NoTrajectory { entry: entry.to_owned() });
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
        return Err(GeneratorEntryError::Extra {
            entry: entry.to_owned(),
            extra: extra.to_owned(),
        });
    }
    Ok((trajectory.to_owned(), GeneratorPolicy { approximation, merge }))
}

fn rule<T: Clone>(
    entry: &str,
    kind: &'static str,
    word: &str,
    rules: &[(&str, T)],
) -> Result<T, GeneratorEntryError> {
    let word = word.trim();
    if let Some((_, r)) = rules.iter().find(|(w, _)| *w == word) {
        return Ok(r.clone());
    }
    let names: Vec<&str> = rules.iter().map(|(w, _)| *w).collect();
    let hint = closest_name(word, names.iter().copied())
        .map(|s| format!("did you mean `{s}`? "))
        .unwrap_or_default();
    Err(GeneratorEntryError::UnknownRule {
        entry: entry.to_owned(),
        rule: kind,
        word: word.to_owned(),
        hint,
        known: names.join(", "),
    })
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
        assert!(matches!(
            parse_generator(":linear"),
            Err(GeneratorEntryError::NoTrajectory { .. })
        ));
        assert!(parse_generator("alt:linear:median:x").unwrap_err().to_string().contains(":x"));
    }
}
