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

use std::sync::{Arc, Weak};

use esgm_core::esgm::{CompUnit, ComputeError, SensorError, SensorInterface};
use esgm_core::{EntityStructure, EntityStructureType, Time};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::runtime::Runtime;
use crate::sample::Sample;
use crate::values::attributes;

/// What a Python unit or sensor needs to turn its answers into structures.
#[derive(Debug)]
struct Output {
    /// Its Python object.
    object: Py<PyAny>,
    /// The name it was registered under (for its log lines).
    name: String,
    /// The type of what it produces.
    type_name: String,
    /// The runtime, for nested frame types (weak: the runtime holds this unit).
    runtime: Weak<Runtime>,
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
        Python::attach(|py| {
            let answer = args(py).and_then(|a| self.object.bind(py).call_method1(method, a));
            let answer = match answer {
                Ok(a) => a,
                Err(e) => return Err(Missed::Failed(self.traceback(py, &e))),
            };
            if answer.is_none() {
                return Err(Missed::NoValue);
            }
            self.structure(&answer).map_err(|e| Missed::Failed(self.traceback(py, &e)))
        })
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

/// A unit written in Python.
#[derive(Debug)]
pub struct PyUnit(Output);

impl PyUnit {
    /// `object` as the unit `name` producing `type_name`.
    pub fn new(object: Py<PyAny>, name: &str, type_name: &str, runtime: &Arc<Runtime>) -> Self {
        Self(Output {
            object,
            name: name.to_owned(),
            type_name: type_name.to_owned(),
            runtime: Arc::downgrade(runtime),
        })
    }
}

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
        self.0
            .call("compute", |py| {
                pyo3::types::PyTuple::new(
                    py,
                    [samples(py, inputs)?.into_any(), qtime.into_pyobject(py)?.into_any()],
                )
            })
            .map_err(compute_error)
    }

    fn compute_at(
        &self,
        inputs: &[esgm_core::Sample],
        t: Time,
    ) -> Result<EntityStructure, ComputeError> {
        let has =
            Python::attach(|py| self.0.object.bind(py).hasattr("compute_at").unwrap_or(false));
        if !has {
            return Err(ComputeError::OperationNotSupported);
        }
        self.0
            .call("compute_at", |py| {
                pyo3::types::PyTuple::new(
                    py,
                    [samples(py, inputs)?.into_any(), t.into_pyobject(py)?.into_any()],
                )
            })
            .map_err(compute_error)
    }
}

/// A sensor written in Python.
#[derive(Debug)]
pub struct PySensor(Output);

impl PySensor {
    /// `object` as the sensor `name` producing `type_name`.
    pub fn new(object: Py<PyAny>, name: &str, type_name: &str, runtime: &Arc<Runtime>) -> Self {
        Self(Output {
            object,
            name: name.to_owned(),
            type_name: type_name.to_owned(),
            runtime: Arc::downgrade(runtime),
        })
    }
}

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
