//! A trajectory handle: the seed's `EntityTrajectoryStructure` operations with their
//! names (`add`, `create_at`, `get_latest`, `get_between`, …), times in nanoseconds,
//! attributes as a `dict`. Calls that may wait release the GIL.

use std::sync::Arc;
use std::time::Duration;

use esgm_core::{
    AddOutcome, EntityStructure, EntityStructureType, EntityTrajectoryStructure,
    InProcessTrajectory, RecvError, SubscribeOptions,
};
use pyo3::exceptions::{PyTimeoutError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::to_py;
use crate::images::ImageBuffer;
use crate::runtime::Runtime;
use crate::sample::Sample;
use crate::values::attributes;

/// A trajectory of the system.
#[pyclass(frozen, module = "esgm")]
#[derive(Debug)]
pub struct Trajectory {
    pub(crate) handle: InProcessTrajectory,
    pub(crate) runtime: Arc<Runtime>,
}

fn outcome(o: AddOutcome) -> &'static str {
    match o {
        AddOutcome::Added => "added",
        AddOutcome::Forwarded => "forwarded",
        AddOutcome::Held { .. } => "held",
        _ => "accepted",
    }
}

impl Trajectory {
    fn entity_type(&self) -> PyResult<EntityStructureType> {
        self.handle.entity_type().map_err(|e| to_py(&e))
    }

    /// `attributes` as a structure `name` valid at `valid_time`, checked against the
    /// trajectory's type as Python values are converted.
    fn structure(
        &self,
        name: &str,
        valid_time: i64,
        create_time: Option<i64>,
        attrs: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<EntityStructure> {
        let ty = self.entity_type()?;
        let types = |t: &str| self.runtime.entity_type(t);
        let mut es = EntityStructure::new(name, valid_time, create_time.unwrap_or(valid_time));
        if let Some(d) = attrs {
            es.attributes = attributes(d, &ty, &types, &[])?;
        }
        Ok(es)
    }

    fn add_with(
        &self,
        py: Python<'_>,
        es: EntityStructure,
        blocking: bool,
    ) -> PyResult<&'static str> {
        let h = self.handle.clone();
        let added = py.detach(move || if blocking { h.add_blocking(es) } else { h.add(es) });
        added.map(outcome).map_err(|e| to_py(&e))
    }
}

#[pymethods]
impl Trajectory {
    /// Its name.
    #[getter]
    fn name(&self) -> &str {
        self.handle.name()
    }

    /// Adds the structure `name` valid at `valid_time` (ns) with `attributes`;
    /// returns `"added"`, `"held"` (a delay policy releases it later) or
    /// `"forwarded"` (sent to its writer in another process).
    #[pyo3(signature = (name, valid_time, attributes=None, create_time=None))]
    fn add(
        &self,
        py: Python<'_>,
        name: &str,
        valid_time: i64,
        attributes: Option<&Bound<'_, PyDict>>,
        create_time: Option<i64>,
    ) -> PyResult<&'static str> {
        let es = self.structure(name, valid_time, create_time, attributes)?;
        self.add_with(py, es, false)
    }

    /// [`add`], waiting for the writer's gate (T4): a violation raises
    /// `PolicyViolation`.
    #[pyo3(signature = (name, valid_time, attributes=None, create_time=None))]
    fn add_blocking(
        &self,
        py: Python<'_>,
        name: &str,
        valid_time: i64,
        attributes: Option<&Bound<'_, PyDict>>,
        create_time: Option<i64>,
    ) -> PyResult<&'static str> {
        let es = self.structure(name, valid_time, create_time, attributes)?;
        self.add_with(py, es, true)
    }

    /// The seed's `create_at`: a structure made and added at `valid_time`.
    #[pyo3(signature = (name, valid_time, attributes=None))]
    fn create_at(
        &self,
        py: Python<'_>,
        name: &str,
        valid_time: i64,
        attributes: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<&'static str> {
        let es = self.structure(name, valid_time, None, attributes)?;
        self.add_with(py, es, false)
    }

    /// The seed's `create_at_now`: valid now.
    #[pyo3(signature = (name, attributes=None))]
    fn create_at_now(
        &self,
        py: Python<'_>,
        name: &str,
        attributes: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<&'static str> {
        let now = esgm_core::Clock::now(&esgm_core::SystemClock);
        let es = self.structure(name, now, None, attributes)?;
        self.add_with(py, es, false)
    }

    /// The latest sample.
    fn get_latest(&self) -> PyResult<Sample> {
        self.handle.get_latest().map(Sample::new).map_err(|e| to_py(&e))
    }

    /// The `n`-th latest sample (0: the latest).
    fn get_nth_latest(&self, n: usize) -> PyResult<Sample> {
        self.handle.get_nth_latest(n).map(Sample::new).map_err(|e| to_py(&e))
    }

    /// Samples valid from `start` to `end` (ns), in valid-time order.
    fn get_between(&self, start: i64, end: i64) -> PyResult<Vec<Sample>> {
        self.handle
            .get_between(start, end)
            .map(|v| v.into_iter().map(Sample::new).collect())
            .map_err(|e| to_py(&e))
    }

    /// The sample valid exactly at `t`.
    fn get_at(&self, t: i64) -> PyResult<Sample> {
        self.handle.get_at(t).map(Sample::new).map_err(|e| to_py(&e))
    }

    /// The sample valid at `t` or the closest before it.
    fn get_closest_at_or_before(&self, t: i64) -> PyResult<Sample> {
        self.handle.get_closest_at_or_before(t).map(Sample::new).map_err(|e| to_py(&e))
    }

    /// Every sample that enters the trajectory from now on: iterate it, or
    /// `recv(timeout)`.
    #[pyo3(signature = (queue=64))]
    fn subscribe(&self, queue: usize) -> PyResult<Subscription> {
        let options = SubscribeOptions::default().capacity(queue);
        let sub = self.handle.subscribe(options).map_err(|e| to_py(&e))?;
        Ok(Subscription { sub })
    }

    /// The structures its policy refuses from now on (T4), each a `dict`
    /// (`constraint`, `valid_time`, `detail`, …): iterate it, or `recv(timeout)`.
    #[pyo3(signature = (queue=64))]
    fn subscribe_violations(&self, queue: usize) -> PyResult<Violations> {
        let sub = self.handle.subscribe_violations(queue).map_err(|e| to_py(&e))?;
        Ok(Violations { sub })
    }

    /// A buffer of this trajectory's memory for one image's pixels (format 0: rgb8, 1:
    /// mono8): write its `array`, then add it as the `image_data` attribute.
    #[pyo3(signature = (width, height, format=0))]
    fn image_buffer(&self, width: i64, height: i64, format: i64) -> PyResult<ImageBuffer> {
        ImageBuffer::new(&self.handle, width, height, format)
    }

    /// Forgets every sample (E7), here and in every process that holds it.
    fn reset(&self, py: Python<'_>) -> PyResult<()> {
        let h = self.handle.clone();
        py.detach(move || h.reset()).map_err(|e| to_py(&e))
    }

    /// Its statistics: added, stored, dropped by cause, delays.
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let stats = self.handle.stats().map_err(|e| to_py(&e))?;
        crate::runtime::json_to_py(
            py,
            &serde_json::to_value(stats).map_err(|e| PyTypeError::new_err(e.to_string()))?,
        )
    }

    /// Why the trajectory has not produced since `since` (ns; None: since it was
    /// made), as a dict: `reasons` in words, then `inputs`, the producer's `worker`
    /// counters and `recent_calls`, a sync's `sync` (with what it `dropped` per input
    /// and reason), `missed` sample points with their cause, `drops` per cause with
    /// the last one, `writer_alive` and `writer_changed` (a restart or take-over).
    /// Answered by the process that writes it.
    #[pyo3(signature = (since=None))]
    fn why<'py>(&self, py: Python<'py>, since: Option<i64>) -> PyResult<Bound<'py, PyAny>> {
        let (rt, name) = (Arc::clone(&self.runtime), self.handle.name().to_owned());
        let since = since.unwrap_or(i64::MIN);
        let why = py
            .detach(move || match &*rt {
                Runtime::Local(e) => esgm_core::Esgm::why(e, &name, since),
                Runtime::Shm(e) => esgm_core::Esgm::why(e, &name, since),
            })
            .map_err(|e| to_py(&e))?;
        crate::runtime::json_to_py(
            py,
            &serde_json::to_value(why).map_err(|e| PyTypeError::new_err(e.to_string()))?,
        )
    }

    fn __repr__(&self) -> String {
        format!("Trajectory({:?})", self.handle.name())
    }
}

/// A subscription: the samples entering a trajectory, in order.
#[pyclass(module = "esgm")]
#[derive(Debug)]
pub struct Subscription {
    sub: esgm_core::Subscription<esgm_core::Sample>,
}

/// The next item of `sub`, waiting at most `timeout` seconds (`None`: for ever) with
/// the GIL released, looking at Python's signals (Ctrl-C) between slices; raises
/// `TimeoutError` naming `what` when none came. Shared by samples and violations.
fn recv_within<T>(
    py: Python<'_>,
    sub: &esgm_core::Subscription<T>,
    timeout: Option<f64>,
    what: &str,
) -> PyResult<T>
where
    T: Send,
{
    let deadline = match timeout {
        Some(t) if !(t.is_finite() && t >= 0.0) => {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "timeout {t} is not a time"
            )));
        }
        Some(t) => Some(std::time::Instant::now() + Duration::from_secs_f64(t)),
        None => None,
    };
    loop {
        let slice = deadline.map_or(SIGNAL_CHECK, |d| {
            d.saturating_duration_since(std::time::Instant::now()).min(SIGNAL_CHECK)
        });
        match py.detach(|| sub.recv_timeout(slice)) {
            Ok(item) => return Ok(item),
            Err(RecvError::Timeout) => {
                py.check_signals()?;
                if deadline.is_some_and(|d| std::time::Instant::now() >= d) {
                    return Err(PyTimeoutError::new_err(format!("no {what} within the timeout")));
                }
            }
            Err(e) => return Err(crate::errors::EsgmError::new_err(e.to_string())),
        }
    }
}

/// How long one wait lasts before Python's signals (Ctrl-C) are looked at.
const SIGNAL_CHECK: Duration = Duration::from_millis(100);

#[pymethods]
impl Subscription {
    /// The next sample, waiting at most `timeout` seconds (`None`: for ever); raises
    /// `TimeoutError` when none came.
    #[pyo3(signature = (timeout=None))]
    fn recv(&self, py: Python<'_>, timeout: Option<f64>) -> PyResult<Sample> {
        recv_within(py, &self.sub, timeout, "sample").map(Sample::new)
    }

    /// Samples dropped because this subscription's queue was full.
    #[getter]
    fn overflowed(&self) -> u64 {
        self.sub.overflowed()
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&self, py: Python<'_>) -> PyResult<Option<Sample>> {
        match self.recv(py, None) {
            Ok(s) => Ok(Some(s)),
            Err(e) if e.is_instance_of::<crate::errors::EsgmError>(py) => Ok(None),
            Err(e) => Err(e),
        }
    }
}

/// A subscription to a trajectory's policy violations.
#[pyclass(module = "esgm")]
#[derive(Debug)]
pub struct Violations {
    sub: esgm_core::Subscription<esgm_core::PolicyViolation>,
}

#[pymethods]
impl Violations {
    /// The next violation as a `dict`, waiting at most `timeout` seconds (`None`: for
    /// ever); raises `TimeoutError` when none came.
    #[pyo3(signature = (timeout=None))]
    fn recv<'py>(&self, py: Python<'py>, timeout: Option<f64>) -> PyResult<Bound<'py, PyAny>> {
        let v = recv_within(py, &self.sub, timeout, "violation")?;
        let json = serde_json::to_value(&v).map_err(|e| PyTypeError::new_err(e.to_string()))?;
        crate::runtime::json_to_py(py, &json)
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        match self.recv(py, None) {
            Ok(v) => Ok(Some(v)),
            Err(e) if e.is_instance_of::<crate::errors::EsgmError>(py) => Ok(None),
            Err(e) => Err(e),
        }
    }
}
