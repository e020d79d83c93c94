//! Times on the command line: absolute nanoseconds, RFC 3339, or relative to the
//! trajectory's latest valid time (`-5s`, `-100ms`, `+1s`, `latest`).

use std::time::UNIX_EPOCH;

use anyhow::{Context, bail};
use esgm_core::Time;

/// A time as written by the user, resolved once the latest valid time is known.
#[derive(Debug, Clone, PartialEq)]
pub enum TimeArg {
    /// Nanoseconds since the Unix epoch.
    Absolute(Time),
    /// Latest valid time plus this many nanoseconds (negative: before).
    Relative(Time),
}

impl std::str::FromStr for TimeArg {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> anyhow::Result<Self> {
        let s = s.trim();
        if s == "latest" {
            return Ok(Self::Relative(0));
        }
        if let Ok(ns) = s.parse::<Time>() {
            return Ok(Self::Absolute(ns));
        }
        if let Some(rest) = s.strip_prefix('-').or_else(|| s.strip_prefix('+')) {
            let d = humantime::parse_duration(rest)
                .with_context(|| format!("`{s}` is not a relative time like -5s or -100ms"))?;
            let ns = Time::try_from(d.as_nanos()).context("relative time too large")?;
            return Ok(Self::Relative(if s.starts_with('-') { -ns } else { ns }));
        }
        match humantime::parse_rfc3339_weak(s) {
            Ok(t) => {
                let d = t.duration_since(UNIX_EPOCH).context("time before 1970")?;
                Ok(Self::Absolute(Time::try_from(d.as_nanos()).context("time too large")?))
            }
            // The last form tried: the message lists every form, more use than RFC 3339's error.
            Err(_) => bail!(
                "`{s}` is not a time: give nanoseconds, RFC 3339 (2026-11-21T10:00:00Z) or \
                 relative to the latest sample (-5s, -100ms)"
            ),
        }
    }
}

impl TimeArg {
    /// The absolute time, given the trajectory's latest valid time.
    pub fn resolve(&self, latest: Option<Time>) -> anyhow::Result<Time> {
        match (self, latest) {
            (Self::Absolute(t), _) => Ok(*t),
            (Self::Relative(d), Some(l)) => Ok(l.saturating_add(*d)),
            (Self::Relative(_), None) => {
                bail!("a relative time needs a latest sample, and the trajectory is empty")
            }
        }
    }
}

/// A time for display: RFC 3339 with nanoseconds when it is a plausible wall-clock time.
pub fn display(t: Time) -> String {
    if (0..=4_102_444_800_000_000_000).contains(&t) {
        let st = UNIX_EPOCH + std::time::Duration::from_nanos(t as u64);
        humantime::format_rfc3339_nanos(st).to_string()
    } else {
        t.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_form_parses() {
        assert_eq!("123".parse::<TimeArg>().unwrap(), TimeArg::Absolute(123));
        assert_eq!("-5s".parse::<TimeArg>().unwrap(), TimeArg::Relative(-5_000_000_000));
        assert_eq!("-100ms".parse::<TimeArg>().unwrap(), TimeArg::Relative(-100_000_000));
        assert_eq!("latest".parse::<TimeArg>().unwrap(), TimeArg::Relative(0));
        assert_eq!(
            "1970-01-01T00:00:01Z".parse::<TimeArg>().unwrap(),
            TimeArg::Absolute(1_000_000_000)
        );
        let e = "yesterday".parse::<TimeArg>().unwrap_err().to_string();
        assert!(e.contains("`yesterday` is not a time"), "{e}");
        assert_eq!(TimeArg::Relative(-5).resolve(Some(10)).unwrap(), 5);
        assert!(TimeArg::Relative(-5).resolve(None).is_err());
    }
}
