//! Times in remote queries, as the `esgm` command takes them: nanoseconds, RFC 3339
//! (`2026-11-21T10:00:00Z`), or relative to the trajectory's latest valid time
//! (`-5s`, `-100ms`), resolved by the bridge that answers.

use esgm_core::Time;

/// Resolves `s` against the latest valid time (`None`: the trajectory is empty).
pub fn resolve(s: &str, latest: Option<Time>) -> Result<Time, String> {
    if let Ok(ns) = s.parse::<i64>() {
        return Ok(ns);
    }
    if let Some(rest) = s.strip_prefix('-').or_else(|| s.strip_prefix('+')) {
        let d = humantime::parse_duration(rest).map_err(|e| format!("time `{s}`: {e}"))?;
        let d = i64::try_from(d.as_nanos()).map_err(|_| format!("time `{s}` is too far"))?;
        let latest =
            latest.ok_or_else(|| format!("time `{s}` is relative, but the trajectory is empty"))?;
        return Ok(if s.starts_with('-') { latest - d } else { latest + d });
    }
    let t = humantime::parse_rfc3339_weak(s)
        .map_err(|_| format!("time `{s}`: not nanoseconds, RFC 3339 or -DURATION"))?;
    let since = t
        .duration_since(std::time::UNIX_EPOCH)
        .map_err(|_| format!("time `{s}` is before 1970"))?;
    i64::try_from(since.as_nanos()).map_err(|_| format!("time `{s}` is too far"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_form() {
        assert_eq!(resolve("42", None), Ok(42));
        assert_eq!(resolve("-5s", Some(10_000_000_000)), Ok(5_000_000_000));
        assert!(resolve("-5s", None).is_err());
        assert_eq!(resolve("1970-01-01T00:00:01Z", None), Ok(1_000_000_000));
        assert!(resolve("soon", None).is_err());
    }
}
