//! Computational units and sensors written in Python.
//!
//! A unit is any object with `compute(inputs, qtime)` (and optionally
//! `compute_at(inputs, t)`): `inputs` are [`Sample`]s, one per input trajectory, and it
//! returns `(name, valid_time, attributes)`, or `None` for no output this time (the
//! seed's `ValueNotAvailable`). A sensor has `get_current_value(qtime)`, returning the
//! same. esgm calls them on its worker threads, holding the GIL only for the call.
//!
//! A Python exception never kills the worker: it is logged with its traceback and
//! counted as a failed call (the worker's `failures`), and the next input is computed
//! as usual.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Weak};
use std::time::{Duration, Instant};

use esgm_core::esgm::{CompUnit, ComputeError, SensorError, SensorInterface};
use esgm_core::{EntityStructure, EntityStructureType, Time};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::runtime::Runtime;
use crate::sample::Sample;
use crate::values::attributes;

/// Set when the interpreter is about to shut down ([`shutdown`]): from then on esgm's
/// workers call no Python unit or sensor (a call into a finalizing interpreter crashes
/// the process); their calls fail instead, counted.
static SHUTTING_DOWN: AtomicBool = AtomicBool::new(false);
/// Calls into Python units and sensors under way, which [`shutdown`] waits for.
static IN_FLIGHT: AtomicUsize = AtomicUsize::new(0);

/// One call under way, while it lives.
struct InFlight;

impl InFlight {
    /// A call may start, unless the interpreter is shutting down.
    fn enter() -> Option<Self> {
        IN_FLIGHT.fetch_add(1, Ordering::SeqCst);
        if SHUTTING_DOWN.load(Ordering::SeqCst) {
            IN_FLIGHT.fetch_sub(1, Ordering::SeqCst);
            return None;
        }
        Some(InFlight)
    }
}

impl Drop for InFlight {
    fn drop(&mut self) {
        IN_FLIGHT.fetch_sub(1, Ordering::SeqCst);
    }
}

/// How long [`shutdown`] waits for calls under way (a unit that never returns is not
/// waited for past this).
const SHUTDOWN_WAIT: Duration = Duration::from_secs(2);

/// Registered with `atexit`: stops esgm's workers from calling Python, and waits (the
/// GIL released) for the calls under way to return, before the interpreter finalizes.
#[pyfunction]
pub fn shutdown(py: Python<'_>) {
    SHUTTING_DOWN.store(true, Ordering::SeqCst);
    py.detach(|| {
        let deadline = Instant::now() + SHUTDOWN_WAIT;
        while IN_FLIGHT.load(Ordering::SeqCst) > 0 && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(1));
        }
    });
}

/// What a Python unit or sensor needs to turn its answers into structures.
#[derive(Debug)]
pub struct Output {
    /// Its Python object.
    object: Py<PyAny>,
    /// The name it was registered under (for its log lines).
    name: String,
    /// The type of what it produces.
    type_name: String,
    /// The runtime, for nested frame types (weak: the runtime holds this unit).
    runtime: Weak<Runtime>,
}

impl Output {
    /// `object`, registered as `name`, producing `type_name` in `runtime`.
    pub fn new(object: Py<PyAny>, name: &str, type_name: &str, runtime: &Arc<Runtime>) -> Self {
        Self {
            object,
            name: name.to_owned(),
            type_name: type_name.to_owned(),
            runtime: Arc::downgrade(runtime),
        }
    }
}

/// Why a call produced nothing.
enum Missed {
    NoValue,
    Failed(String),
}

impl Output {
    fn call(
        &self,
        method: &str,
        args: impl for<'py> FnOnce(Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyTuple>>,
    ) -> Result<EntityStructure, Missed> {
        let shutting_down = || Missed::Failed("the Python interpreter is shutting down".into());
        let Some(_call) = InFlight::enter() else { return Err(shutting_down()) };
        let called = Python::try_attach(|py| {
            let answer = args(py).and_then(|a| self.object.bind(py).call_method1(method, a));
            let answer = match answer {
                Ok(a) => a,
                Err(e) => return Err(Missed::Failed(self.traceback(py, &e))),
            };
            if answer.is_none() {
                return Err(Missed::NoValue);
            }
            self.structure(&answer).map_err(|e| Missed::Failed(self.traceback(py, &e)))
        });
        called.unwrap_or_else(|| Err(shutting_down()))
    }

    /// `(name, valid_time, attributes)` as a structure of this unit's type.
    fn structure(&self, answer: &Bound<'_, PyAny>) -> PyResult<EntityStructure> {
        let (name, valid_time, attrs): (String, i64, Bound<'_, PyDict>) =
            answer.extract().map_err(|_| {
                pyo3::exceptions::PyTypeError::new_err(format!(
                    "`{}` must return (name, valid_time, attributes) or None",
                    self.name
                ))
            })?;
        let runtime = self.runtime.upgrade().ok_or_else(|| {
            pyo3::exceptions::PyRuntimeError::new_err("the ESGM this unit belongs to is gone")
        })?;
        let ty: EntityStructureType = runtime.entity_type(&self.type_name).ok_or_else(|| {
            pyo3::exceptions::PyTypeError::new_err(format!("no type `{}`", self.type_name))
        })?;
        let types = |t: &str| runtime.entity_type(t);
        let mut es = EntityStructure::new(name, valid_time, valid_time);
        es.attributes = attributes(&attrs, &ty, &types, &[])?;
        Ok(es)
    }

    /// The exception with its traceback, logged once here and returned as the reason.
    fn traceback(&self, py: Python<'_>, e: &PyErr) -> String {
        let text = py
            .import("traceback")
            .and_then(|tb| tb.call_method1("format_exception", (e.clone_ref(py),)))
            .and_then(|lines| lines.extract::<Vec<String>>())
            .map_or_else(|_| e.to_string(), |lines| lines.concat());
        // Python's own logging (logger `esgm`), where a Python program's logs go.
        let logged = py.import("logging").and_then(|l| {
            l.call_method1("getLogger", ("esgm",))?.call_method1(
                "error",
                (format!("`{}` raised (counted as a failed call):\n{text}", self.name),),
            )
        });
        if logged.is_err() {
            // No logging module to speak through: the failure is still counted.
            eprintln!("esgm: `{}` raised:\n{text}", self.name);
        }
        e.to_string()
    }
}

fn samples<'py>(
    py: Python<'py>,
    inputs: &[esgm_core::Sample],
) -> PyResult<Bound<'py, pyo3::types::PyList>> {
    let items = inputs
        .iter()
        .map(|s| Bound::new(py, Sample::new(s.clone())))
        .collect::<PyResult<Vec<_>>>()?;
    pyo3::types::PyList::new(py, items)
}

/// A unit written in Python (its object calls `compute`).
#[derive(Debug)]
pub struct PyUnit(pub Output);

fn compute_error(m: Missed) -> ComputeError {
    match m {
        Missed::NoValue => ComputeError::ValueNotAvailable,
        Missed::Failed(reason) => ComputeError::Failed { reason },
    }
}

impl CompUnit for PyUnit {
    fn compute(
        &self,
        inputs: &[esgm_core::Sample],
        qtime: Time,
    ) -> Result<EntityStructure, ComputeError> {
        self.call_with("compute", inputs, qtime)
    }

    fn compute_at(
        &self,
        inputs: &[esgm_core::Sample],
        t: Time,
    ) -> Result<EntityStructure, ComputeError> {
        let has = InFlight::enter().is_some_and(|_call| {
            Python::try_attach(|py| self.0.object.bind(py).hasattr("compute_at").unwrap_or(false))
                .unwrap_or(false)
        });
        if !has {
            return Err(ComputeError::OperationNotSupported);
        }
        self.call_with("compute_at", inputs, t)
    }
}

impl PyUnit {
    /// Calls the unit's `method(inputs, time)`: `compute` and `compute_at` take the
    /// same arguments.
    fn call_with(
        &self,
        method: &str,
        inputs: &[esgm_core::Sample],
        time: Time,
    ) -> Result<EntityStructure, ComputeError> {
        self.0
            .call(method, |py| {
                pyo3::types::PyTuple::new(
                    py,
                    [samples(py, inputs)?.into_any(), time.into_pyobject(py)?.into_any()],
                )
            })
            .map_err(compute_error)
    }
}

/// A sensor written in Python (its object calls `get_current_value`).
#[derive(Debug)]
pub struct PySensor(pub Output);

impl SensorInterface for PySensor {
    fn get_current_value(&self, qtime: Time) -> Result<EntityStructure, SensorError> {
        self.0.call("get_current_value", |py| pyo3::types::PyTuple::new(py, [qtime])).map_err(|m| {
            match m {
                Missed::NoValue => SensorError::ValueNotAvailable,
                Missed::Failed(reason) => SensorError::Failed { reason },
            }
        })
    }
}
