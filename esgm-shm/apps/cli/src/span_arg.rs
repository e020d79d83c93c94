//! Seconds and rates on the command line, checked when parsed: `--seconds inf` or a rate
//! of `1e-20` is refused by clap with the reason, instead of panicking once the whole
//! system has been started (`Duration::from_secs_f64` panics on them).

use esgm_core::time::{period_from_rate, span_from_seconds};

/// A `--seconds`/`--interval`-like argument: finite, ≥ 0, at most 100 years.
pub fn seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("`{s}` is not a number of seconds"))?;
    span_from_seconds(v).map_err(|e| format!("seconds: {e}"))?;
    Ok(v)
}

/// A `--minutes` argument: as [`seconds`], sixty times over.
pub fn minutes(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("`{s}` is not a number of minutes"))?;
    span_from_seconds(v * 60.0).map_err(|e| format!("minutes: {e}"))?;
    Ok(v)
}

/// A rate in Hz (or a speed factor): finite, > 0, its period at most 100 years.
pub fn rate(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("`{s}` is not a rate"))?;
    period_from_rate(v).map_err(|e| format!("rate: {e}"))?;
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_would_panic_later_is_refused_when_parsed() {
        assert!(seconds("inf").unwrap_err().contains("finite"));
        assert!(seconds("NaN").is_err());
        assert!(seconds("-3").unwrap_err().contains("range"));
        assert!(seconds("abc").unwrap_err().contains("not a number"));
        assert_eq!(seconds("2.5"), Ok(2.5));
        assert!(minutes("1e300").is_err());
        assert_eq!(minutes("10"), Ok(10.0));
        assert!(rate("1e-20").unwrap_err().contains("100 years"));
        assert!(rate("0").is_err());
        assert_eq!(rate("30"), Ok(30.0));
    }
}
