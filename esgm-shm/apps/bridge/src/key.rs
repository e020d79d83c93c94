//! Key expressions: where a trajectory lives on Zenoh.
//!
//! A trajectory `<trajectory>` of the domain `<domain>` is published on
//! `esgm/<domain>/<trajectory>`, and the exporting bridge answers queries on the same
//! key (its history for late joiners, its type, and the seed's queries from other
//! hosts). Domain and trajectory names are made of `[A-Za-z0-9_.:-]` (esgm's own rule
//! for names), so they never contain Zenoh's separators or wildcards: `esgm/lab/*`
//! is every trajectory of `lab`, `esgm/*/robot_state` one trajectory of every domain,
//! `esgm/**` everything.
//!
//! The query parameter `esgm` says what a query asks ([`Ask`]).

/// The first chunk of every esgm key.
pub const ROOT: &str = "esgm";

/// The key of `trajectory` in `domain`.
pub fn data_key(domain: &str, trajectory: &str) -> String {
    format!("{ROOT}/{domain}/{trajectory}")
}

/// Every trajectory of `domain`: what a bridge's queryable serves.
pub fn domain_key(domain: &str) -> String {
    format!("{ROOT}/{domain}/*")
}

/// The domain and trajectory of a concrete data key; `None` for anything else.
pub fn parse(key: &str) -> Option<(&str, &str)> {
    let mut chunks = key.split('/');
    match (chunks.next(), chunks.next(), chunks.next(), chunks.next()) {
        (Some(ROOT), Some(domain), Some(trajectory), None)
            if is_name(domain) && is_name(trajectory) =>
        {
            Some((domain, trajectory))
        }
        _ => None,
    }
}

/// True for a name esgm accepts as a domain or trajectory.
pub fn is_name(name: &str) -> bool {
    !name.is_empty()
        && name.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | ':'))
}

/// What `--import` names: `<domain>/<trajectory>` (either may be `*`), or a key
/// expression starting with `esgm/`.
pub fn import_key(spec: &str) -> Result<String, String> {
    if spec.starts_with(&format!("{ROOT}/")) {
        return Ok(spec.to_owned());
    }
    match spec.split_once('/') {
        Some((d, t)) if (d == "*" || is_name(d)) && (t == "*" || t == "**" || is_name(t)) => {
            Ok(format!("{ROOT}/{d}/{t}"))
        }
        _ => Err(format!(
            "`{spec}` is neither `<domain>/<trajectory>` nor a key expression starting with `{ROOT}/`"
        )),
    }
}

/// The query parameter that says what a query asks.
pub const ASK: &str = "esgm";

/// What a query on a trajectory's key asks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ask {
    /// The type and cache of every exported trajectory the key matches (JSON).
    Meta,
    /// The exporter's history of the trajectory: one message per sample, oldest first.
    History,
    /// `latest`.
    Latest,
    /// `nth` (parameter `n`).
    Nth,
    /// `between` (parameters `from`, `to`).
    Between,
    /// `at` (parameter `t`).
    At,
    /// `closest` (parameter `t`).
    Closest,
}

impl Ask {
    /// Every ask, by its parameter value.
    pub const ALL: [(&'static str, Ask); 7] = [
        ("meta", Ask::Meta),
        ("history", Ask::History),
        ("latest", Ask::Latest),
        ("nth", Ask::Nth),
        ("between", Ask::Between),
        ("at", Ask::At),
        ("closest", Ask::Closest),
    ];

    /// The parameter value.
    pub fn as_str(self) -> &'static str {
        Self::ALL.iter().find(|(_, a)| *a == self).map_or("meta", |(s, _)| s)
    }

    /// The ask named `s`.
    pub fn parse(s: &str) -> Option<Ask> {
        Self::ALL.iter().find(|(n, _)| *n == s).map(|(_, a)| *a)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys() {
        assert_eq!(data_key("lab", "robot_state"), "esgm/lab/robot_state");
        assert_eq!(parse("esgm/lab/robot_state"), Some(("lab", "robot_state")));
        assert_eq!(parse("esgm/lab/*"), None);
        assert_eq!(parse("esgm/lab/a/b"), None);
        assert_eq!(import_key("lab/robot_state").as_deref(), Ok("esgm/lab/robot_state"));
        assert_eq!(import_key("lab/*").as_deref(), Ok("esgm/lab/*"));
        assert_eq!(import_key("esgm/**").as_deref(), Ok("esgm/**"));
        assert!(import_key("robot_state").is_err());
        for (s, a) in Ask::ALL {
            assert_eq!(Ask::parse(s), Some(a));
            assert_eq!(a.as_str(), s);
        }
    }
}
