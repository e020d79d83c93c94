//! A trajectory's fluent stream policy (C1–C6) as words: the same settings on the
//! command line (`esgm traj create … --cache 10 --order monotone`) and in a
//! configuration file (`policy = { cache = 10, order = "monotone" }`), declared once
//! here so the two never drift apart.
//!
//! | setting | values |
//! | --- | --- |
//! | `cache` (C2) | `all`, a count (`10`), or a duration of valid time (`5s`) |
//! | `change` (C1) | `none`, `any-change`, `any-update`, `every 100ms` |
//! | `filter` (C3) | a predicate over attributes, e.g. `size > 10 && x < 320` |
//! | `from`, `to` (C4) | valid-time bounds: nanoseconds or RFC 3339; `0` = creation / forever |
//! | `order` (C5) | `any`, `monotone`, `strict` |
//! | `delay` (C6) | `any` or a duration (`50ms`) |
//! | `reorder` | `true` / `false`: hold samples for the delay and release them in order |
//!
//! Durations are humantime words (`250ms`, `1s`, `2m`) or integer nanoseconds.

use anyhow::{Context, bail};
use esgm_core::policy::{
    CacheConstraint, ChangeConstraint, DelayConstraint, DurationConstraint, OrderConstraint,
};
use esgm_core::{FluentStreamPolicy, Time};
use serde::Deserialize;

use crate::time_arg::TimeArg;

/// The policy settings; each one left out keeps the base policy's value.
#[derive(Debug, Clone, Default, PartialEq, clap::Args, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicyArgs {
    /// C2, what is kept: `all`, a count (`10`) or a duration of valid time (`5s`).
    #[arg(long)]
    #[serde(default, deserialize_with = "word")]
    pub cache: Option<String>,
    /// C1, what must differ between samples: `none`, `any-change`, `any-update`,
    /// `every 100ms`.
    #[arg(long)]
    #[serde(default, deserialize_with = "word")]
    pub change: Option<String>,
    /// C3, a predicate samples must satisfy, e.g. `size > 10`.
    #[arg(long)]
    #[serde(default, deserialize_with = "word")]
    pub filter: Option<String>,
    /// C4, the first valid time allowed (ns or RFC 3339; 0 = creation time).
    #[arg(long)]
    #[serde(default, deserialize_with = "word")]
    pub from: Option<String>,
    /// C4, the last valid time allowed (ns or RFC 3339; 0 = forever).
    #[arg(long)]
    #[serde(default, deserialize_with = "word")]
    pub to: Option<String>,
    /// C5, how consecutive valid times relate: `any`, `monotone`, `strict`.
    #[arg(long)]
    #[serde(default, deserialize_with = "word")]
    pub order: Option<String>,
    /// C6, the largest add − valid time: `any` or a duration (`50ms`).
    #[arg(long)]
    #[serde(default, deserialize_with = "word")]
    pub delay: Option<String>,
    /// With a monotone order and a delay, hold samples and release them in order:
    /// `true` or `false`.
    #[arg(long)]
    #[serde(default, deserialize_with = "word")]
    pub reorder: Option<String>,
}

impl PolicyArgs {
    /// `base` with these settings applied, checked by the core's rules; an error names
    /// the setting and what it accepts.
    pub fn apply_to(&self, mut p: FluentStreamPolicy) -> anyhow::Result<FluentStreamPolicy> {
        if let Some(c) = &self.cache {
            p.cache = cache(c).with_context(|| format!("cache = `{c}`"))?;
        }
        if let Some(c) = &self.change {
            p.change = change(c).with_context(|| format!("change = `{c}`"))?;
        }
        if let Some(f) = &self.filter {
            p.filter = Some(f.clone());
        }
        if self.from.is_some() || self.to.is_some() {
            let (from, to) = match p.duration {
                DurationConstraint::Between { from, to } => (from, to),
                DurationConstraint::Unbounded => (0, 0),
            };
            let from = self.from.as_deref().map_or(Ok(from), |s| absolute("from", s))?;
            let to = self.to.as_deref().map_or(Ok(to), |s| absolute("to", s))?;
            p.duration = DurationConstraint::Between { from, to };
        }
        if let Some(o) = &self.order {
            p.order = match o.as_str() {
                "any" => OrderConstraint::Any,
                "monotone" => OrderConstraint::Monotone,
                "strict" | "strict-monotone" => OrderConstraint::StrictMonotone,
                _ => bail!("order = `{o}`: expected any, monotone or strict"),
            };
        }
        if let Some(d) = &self.delay {
            p.delay = match d.as_str() {
                "any" => DelayConstraint::Any,
                _ => DelayConstraint::Max(duration(d).with_context(|| format!("delay = `{d}`"))?),
            };
        }
        if let Some(r) = &self.reorder {
            p.reorder = r
                .parse()
                .map_err(|_| anyhow::anyhow!("reorder = `{r}`: expected true or false"))?;
        }
        p.validate()?;
        Ok(p)
    }
}

/// A duration: humantime words (`250ms`) or integer nanoseconds; positive.
pub fn duration(s: &str) -> anyhow::Result<Time> {
    let ns = match s.trim().parse::<Time>() {
        Ok(ns) => ns,
        // Not plain nanoseconds: the humantime error is the one reported.
        Err(_) => {
            let d = humantime::parse_duration(s.trim())
                .map_err(|_| anyhow::anyhow!("`{s}` is not a duration like 250ms, 1s or 2m"))?;
            Time::try_from(d.as_nanos()).context("duration too large")?
        }
    };
    if ns <= 0 {
        bail!("`{s}` must be a positive duration");
    }
    Ok(ns)
}

fn cache(s: &str) -> anyhow::Result<CacheConstraint> {
    if s == "all" {
        return Ok(CacheConstraint::All);
    }
    if let Ok(n) = s.parse::<i64>() {
        return Ok(CacheConstraint::from_seed(n)?);
    }
    Ok(CacheConstraint::Duration(
        duration(s).context("expected all, a count or a duration of valid time")?,
    ))
}

fn change(s: &str) -> anyhow::Result<ChangeConstraint> {
    Ok(match s {
        "none" => ChangeConstraint::Unconstrained,
        "any-change" => ChangeConstraint::AnyChange,
        "any-update" => ChangeConstraint::AnyUpdate,
        _ => match s.strip_prefix("every") {
            Some(period) => ChangeConstraint::SampleEvery(duration(period.trim())?),
            None => bail!("expected none, any-change, any-update or `every <duration>`"),
        },
    })
}

fn absolute(field: &str, s: &str) -> anyhow::Result<Time> {
    match s.parse::<TimeArg>() {
        Ok(TimeArg::Absolute(t)) => Ok(t),
        _ => bail!("{field} = `{s}`: expected nanoseconds or an RFC 3339 time (0 = default)"),
    }
}

/// A setting as a word, whether the file wrote it as a string, number or boolean.
fn word<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<String>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Word {
        S(String),
        I(i64),
        F(f64),
        B(bool),
    }
    Ok(Some(match Word::deserialize(d)? {
        Word::S(s) => s,
        Word::I(i) => i.to_string(),
        Word::F(f) => f.to_string(),
        Word::B(b) => b.to_string(),
    }))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn args(f: impl FnOnce(&mut PolicyArgs)) -> PolicyArgs {
        let mut a = PolicyArgs::default();
        f(&mut a);
        a
    }

    #[test]
    fn words_become_constraints() {
        let p = args(|a| {
            a.cache = Some("5s".into());
            a.change = Some("every 100ms".into());
            a.order = Some("monotone".into());
            a.delay = Some("50ms".into());
            a.reorder = Some("false".into());
            a.filter = Some("size > 10".into());
        })
        .apply_to(FluentStreamPolicy::default())
        .unwrap();
        assert_eq!(p.cache, CacheConstraint::Duration(5_000_000_000));
        assert_eq!(p.change, ChangeConstraint::SampleEvery(100_000_000));
        assert_eq!(p.order, OrderConstraint::Monotone);
        assert_eq!(p.delay, DelayConstraint::Max(50_000_000));
        assert!(!p.reorder);
        let p = args(|a| a.cache = Some("10".into())).apply_to(p).unwrap();
        assert_eq!(p.cache, CacheConstraint::Elements(10));
        assert_eq!(p.order, OrderConstraint::Monotone, "unset settings keep the base");
    }

    #[test]
    fn bad_words_name_the_setting() {
        for (a, needle) in [
            (args(|a| a.cache = Some("-3".into())), "cache"),
            (args(|a| a.order = Some("sorted".into())), "order"),
            (args(|a| a.delay = Some("soon".into())), "delay"),
            (args(|a| a.change = Some("every never".into())), "change"),
            (args(|a| a.reorder = Some("maybe".into())), "reorder"),
            (args(|a| a.from = Some("-5s".into())), "from"),
        ] {
            let e = format!("{:#}", a.apply_to(FluentStreamPolicy::default()).unwrap_err());
            assert!(e.contains(needle), "{e}");
        }
    }
}
