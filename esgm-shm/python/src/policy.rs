//! A trajectory's policy (C1–C6) from a Python `dict`.

use esgm_core::{CacheConstraint, DelayConstraint, FluentStreamPolicy, OrderConstraint};
use pyo3::exceptions::{PyKeyError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// `base` with the settings of `{"cache": 10 | "all", "order": "monotone", "delay": ns,
/// "reorder": bool, "filter": "x > 0.0"}` (a kind's own defaults, such as a sampled
/// stream's period, stay unless set); an unknown key or value is named. (The
/// combination is checked when the trajectory is made: `IllegalPolicy`.)
pub fn with_dict(base: FluentStreamPolicy, d: &Bound<'_, PyDict>) -> PyResult<FluentStreamPolicy> {
    let mut p = base;
    for (k, v) in d.iter() {
        let key: String = k.extract()?;
        let bad =
            |expected: &str| PyValueError::new_err(format!("policy `{key}`: expected {expected}"));
        p = match key.as_str() {
            "cache" => match v.extract::<String>() {
                Ok(s) if s == "all" => p.cache(CacheConstraint::All),
                Ok(_) => return Err(bad("a count or \"all\"")),
                Err(_) => match v.extract::<usize>() {
                    Ok(n) if n > 0 => p.cache(CacheConstraint::Elements(n)),
                    _ => return Err(bad("a positive count or \"all\"")),
                },
            },
            "order" => match v.extract::<String>().as_deref() {
                Ok("any") => p.order(OrderConstraint::Any),
                Ok("monotone") => p.order(OrderConstraint::Monotone),
                Ok("strict") => p.order(OrderConstraint::StrictMonotone),
                _ => return Err(bad("\"any\", \"monotone\" or \"strict\"")),
            },
            "delay" => match v.extract::<i64>() {
                Ok(ns) if ns >= 0 => p.delay(DelayConstraint::Max(ns)),
                _ => return Err(bad("nanoseconds, at least 0")),
            },
            "reorder" => p.reorder(v.extract::<bool>().map_err(|_| bad("a bool"))?),
            "filter" => p.filter(v.extract::<String>().map_err(|_| bad("an expression"))?),
            other => {
                return Err(PyKeyError::new_err(format!(
                    "no policy setting `{other}`; there are cache, order, delay, reorder and filter"
                )));
            }
        };
    }
    Ok(p)
}
