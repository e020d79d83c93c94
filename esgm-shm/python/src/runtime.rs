//! The ESGM itself, on either runtime: `esgm.connect(domain)` joins a system of
//! processes in shared memory, `esgm.InProcess()` runs one in this process; both have
//! the same methods, named as the seed's IDL names them.

use std::sync::Arc;

use esgm_core::esgm::TrajectorySpec;
use esgm_core::generator_entry::parse_generator;
use esgm_core::operators::sync::SyncPolicy;
use esgm_core::{EntityStructureType, Esgm as _, InProcessEsgm, InProcessTrajectory};
use esgm_shm::ShmEsgm;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::errors::to_py;
use crate::trajectory::Trajectory;
use crate::units::Output;

/// Either runtime.
#[derive(Debug)]
pub enum Runtime {
    /// In this process.
    Local(InProcessEsgm),
    /// Across processes.
    Shm(ShmEsgm),
}

macro_rules! on {
    ($rt:expr, $e:ident => $body:expr) => {
        match $rt {
            Runtime::Local($e) => $body,
            Runtime::Shm($e) => $body,
        }
    };
}

impl Runtime {
    /// The registered type `name`, if any.
    pub fn entity_type(&self, name: &str) -> Option<EntityStructureType> {
        on!(self, e => e.get_entity_structure_type(name).ok())
    }
}

/// A JSON value as Python (dicts, lists, numbers, strings).
pub fn json_to_py<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        serde_json::Value::Null => py.None().into_bound(py),
        serde_json::Value::Bool(b) => pyo3::types::PyBool::new(py, *b).to_owned().into_any(),
        serde_json::Value::Number(n) => match n.as_i64() {
            Some(i) => i.into_pyobject(py)?.into_any(),
            None => n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any(),
        },
        serde_json::Value::String(s) => pyo3::types::PyString::new(py, s).into_any(),
        serde_json::Value::Array(a) => {
            let items = a.iter().map(|x| json_to_py(py, x)).collect::<PyResult<Vec<_>>>()?;
            PyList::new(py, items)?.into_any()
        }
        serde_json::Value::Object(m) => {
            let d = PyDict::new(py);
            for (k, x) in m {
                d.set_item(k, json_to_py(py, x)?)?;
            }
            d.into_any()
        }
    })
}

/// The ESGM: types and trajectories of one system.
#[pyclass(frozen, module = "esgm")]
#[derive(Debug)]
pub struct Esgm {
    runtime: Arc<Runtime>,
}

impl Esgm {
    /// Makes the trajectory of `spec`, its policy's settings changed by `policy`.
    fn create(
        &self,
        py: Python<'_>,
        spec: TrajectorySpec,
        policy: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Trajectory> {
        let spec = match policy {
            Some(d) => {
                let policy = crate::policy::with_dict(spec.policy.clone(), d)?;
                spec.policy(policy)
            }
            None => spec,
        };
        let rt = Arc::clone(&self.runtime);
        let made = py.detach(move || on!(&*rt, e => e.create_trajectory(spec)));
        made.map(|h| self.handle(h)).map_err(|e| to_py(&e))
    }

    fn handle(&self, h: InProcessTrajectory) -> Trajectory {
        Trajectory { handle: h, runtime: Arc::clone(&self.runtime) }
    }

    fn register(&self, py: Python<'_>, t: EntityStructureType) -> PyResult<()> {
        let rt = Arc::clone(&self.runtime);
        py.detach(move || on!(&*rt, e => e.create_type(t))).map_err(|e| to_py(&e))
    }

    /// The sort of a dataclass field's type hint (and its element type, registered).
    fn sort_of(
        &self,
        py: Python<'_>,
        class: &str,
        field: &str,
        hint: &Bound<'_, PyAny>,
    ) -> PyResult<(esgm_core::ValueSort, Option<String>)> {
        use esgm_core::ValueSort as S;
        let builtins = py.import("builtins")?;
        let is = |name: &str| -> PyResult<bool> { Ok(hint.is(&builtins.getattr(name)?)) };
        // `bool` first: it is an `int` to Python.
        for (name, sort) in [
            ("bool", S::Bool),
            ("int", S::Long),
            ("float", S::Double),
            ("str", S::String),
            ("bytes", S::OctetSeq),
            ("bytearray", S::OctetSeq),
        ] {
            if is(name)? {
                return Ok((sort, None));
            }
        }
        if let Ok(numpy) = py.import("numpy") {
            if hint.is(&numpy.getattr("ndarray")?) {
                return Ok((S::OctetSeq, None));
            }
        }
        let typing = py.import("typing")?;
        let dataclasses = py.import("dataclasses")?;
        if dataclasses.call_method1("is_dataclass", (hint,))?.is_truthy()? {
            return Ok((S::EntityFrame, Some(self.create_type(py, hint)?)));
        }
        if typing.call_method1("get_origin", (hint,))?.is(&builtins.getattr("list")?) {
            let args = typing.call_method1("get_args", (hint,))?;
            let item = args.get_item(0)?;
            for (name, sort) in
                [("int", S::LongSeq), ("float", S::DoubleSeq), ("str", S::SymbolSeq)]
            {
                if item.is(&builtins.getattr(name)?) {
                    return Ok((sort, None));
                }
            }
            if dataclasses.call_method1("is_dataclass", (&item,))?.is_truthy()? {
                return Ok((S::EntityFrameSeq, Some(self.create_type(py, &item)?)));
            }
        }
        Err(PyTypeError::new_err(format!(
            "{class}.{field}: no esgm sort for the type {}; use int, float, bool, str, bytes, numpy.ndarray, list[int|float|str], a dataclass or a list of them",
            hint.repr()?
        )))
    }
}

/// `t` with the attribute `name` of sort `spec` (`"Long"`, `"EntityFrameSeq<Blob>"`).
fn with_attribute(t: EntityStructureType, name: &str, spec: &str) -> PyResult<EntityStructureType> {
    let bad = || PyTypeError::new_err(format!("attribute `{name}`: `{spec}` is not a sort"));
    let (sort, element) = match spec.split_once('<') {
        Some((sort, rest)) => (sort.trim(), Some(rest.strip_suffix('>').ok_or_else(bad)?.trim())),
        None => (spec.trim(), None),
    };
    let sort = esgm_core::ValueSort::parse(sort).ok_or_else(bad)?;
    Ok(match (sort, element) {
        (esgm_core::ValueSort::EntityFrame, Some(e)) => t.frame(name, e),
        (esgm_core::ValueSort::EntityFrameSeq, Some(e)) => t.frame_seq(name, e),
        (esgm_core::ValueSort::EntityFrame | esgm_core::ValueSort::EntityFrameSeq, None) => {
            return Err(PyTypeError::new_err(format!(
                "attribute `{name}`: a frame sort names its element type, e.g. `{spec}<Blob>`"
            )));
        }
        (sort, None) => t.attr(name, sort),
        (_, Some(_)) => return Err(bad()),
    })
}

#[pymethods]
impl Esgm {
    /// The registered types' names.
    fn entity_structure_type_names(&self) -> PyResult<Vec<String>> {
        on!(&*self.runtime, e => e.entity_structure_type_names()).map_err(|e| to_py(&e))
    }

    /// A registered type: `{"name": …, "attributes": [{"name", "sort", "element_type"}]}`.
    fn get_entity_structure_type<'py>(
        &self,
        py: Python<'py>,
        name: &str,
    ) -> PyResult<Bound<'py, PyAny>> {
        let t =
            on!(&*self.runtime, e => e.get_entity_structure_type(name)).map_err(|e| to_py(&e))?;
        json_to_py(py, &serde_json::to_value(&t).map_err(|e| PyTypeError::new_err(e.to_string()))?)
    }

    /// The trajectories' names.
    fn trajectories(&self) -> PyResult<Vec<String>> {
        let listed = on!(&*self.runtime, e => e.trajectories()).map_err(|e| to_py(&e))?;
        Ok(listed.into_iter().map(|t| t.name).collect())
    }

    /// Creates a primitive trajectory `name` of `type_name`, which programs add to,
    /// with an optional `policy` (C1–C6): a dict of `cache` (a count, or `"all"`),
    /// `order` (`"any"`, `"monotone"`, `"strict"`), `delay` (ns, the largest add
    /// delay), `reorder` (bool) and `filter` (an expression, e.g. `"x > 0.0"`).
    #[pyo3(signature = (name, type_name, policy=None))]
    fn create_primitive_entity_trajectory_structure(
        &self,
        py: Python<'_>,
        name: &str,
        type_name: &str,
        policy: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Trajectory> {
        self.create(py, TrajectorySpec::primitive(name, type_name), policy)
    }

    /// A synchronized trajectory `name` (G2): states holding one sample of each of
    /// `inputs` valid at the same time — exactly, or within `tolerance` ns as ROS
    /// message_filters match them (`sync_policy`: `"approximate"`, the default with a
    /// tolerance, or `"epsilon"`), keeping `queue_size` items per input.
    #[pyo3(signature = (name, inputs, tolerance=None, sync_policy=None, queue_size=10, policy=None))]
    #[allow(
        clippy::too_many_arguments,
        reason = "the trajectory's settings, each with its default"
    )]
    fn create_sync_entity_trajectory_structure(
        &self,
        py: Python<'_>,
        name: &str,
        inputs: Vec<String>,
        tolerance: Option<i64>,
        sync_policy: Option<&str>,
        queue_size: usize,
        policy: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Trajectory> {
        let sync = SyncPolicy::from_words(sync_policy, tolerance, queue_size)
            .map_err(|e| PyValueError::new_err(format!("trajectory `{name}`: {e}")))?;
        self.create(py, TrajectorySpec::sync(name, inputs, sync), policy)
    }

    /// A merged trajectory `name` (G3): every sample of `inputs` (one type), as they
    /// come.
    #[pyo3(signature = (name, inputs, policy=None))]
    fn create_merge_entity_trajectory_structure(
        &self,
        py: Python<'_>,
        name: &str,
        inputs: Vec<String>,
        policy: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Trajectory> {
        self.create(py, TrajectorySpec::merge(name, inputs), policy)
    }

    /// A trajectory `name` sampled every `sample_period` ns from fluent generators
    /// (G4): `generators` are `"TRAJ[:APPROXIMATION[:MERGE]]"` (`"robot_state:linear"`);
    /// one gives its values, several their state, and `unit` its temporal function of
    /// them (`compute_at(values, t)`). Read `lag` ns behind each sample time, from
    /// `start` to `end` (0: now, forever).
    #[pyo3(signature = (name, generators, sample_period, unit=None, start=0, end=0, lag=0, policy=None))]
    #[allow(
        clippy::too_many_arguments,
        reason = "the trajectory's settings, each with its default"
    )]
    fn create_generated_entity_trajectory_structure(
        &self,
        py: Python<'_>,
        name: &str,
        generators: Vec<String>,
        sample_period: i64,
        unit: Option<&str>,
        start: i64,
        end: i64,
        lag: i64,
        policy: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Trajectory> {
        if generators.is_empty() {
            return Err(PyValueError::new_err(format!(
                "trajectory `{name}`: generators needs at least one trajectory"
            )));
        }
        let generators = generators
            .iter()
            .map(|g| parse_generator(g))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| PyValueError::new_err(format!("trajectory `{name}`: {e}")))?;
        let spec = match unit {
            Some(unit) => TrajectorySpec::sampled_function(name, unit, generators, sample_period),
            None => TrajectorySpec::sampled_generators(name, generators, sample_period),
        };
        self.create(py, spec.between(start, end).lag(lag), policy)
    }

    /// The trajectory `name`.
    fn get_entity_trajectory_structure(&self, py: Python<'_>, name: &str) -> PyResult<Trajectory> {
        let rt = Arc::clone(&self.runtime);
        let name = name.to_owned();
        let got = py.detach(move || on!(&*rt, e => e.get_entity_trajectory_structure(&name)));
        got.map(|h| self.handle(h)).map_err(|e| to_py(&e))
    }

    /// Destroys the trajectory `name`.
    fn destroy_entity_trajectory_structure(&self, py: Python<'_>, name: &str) -> PyResult<()> {
        let rt = Arc::clone(&self.runtime);
        let name = name.to_owned();
        py.detach(move || on!(&*rt, e => e.destroy_entity_trajectory_structure(&name)))
            .map_err(|e| to_py(&e))
    }

    /// Registers the type `type_name` (E1) with `attributes`, a dict of attribute name
    /// to sort: `"Long"`, `"Double"`, `"String"`, `"OctetSeq"`, … (or `"int"`,
    /// `"float"`, `"str"`, `"bytes"`), a frame as `"EntityFrame<Blob>"`, frames as
    /// `"EntityFrameSeq<Blob>"`.
    fn create_entity_structure_type(
        &self,
        py: Python<'_>,
        type_name: &str,
        attributes: &Bound<'_, PyDict>,
    ) -> PyResult<()> {
        let mut t = EntityStructureType::new(type_name);
        for (k, v) in attributes.iter() {
            let (name, spec): (String, String) = (k.extract()?, v.extract()?);
            t = with_attribute(t, &name, &spec)?;
        }
        self.register(py, t)
    }

    /// Registers a dataclass as a type of the same name (E1): `int` is `Long`,
    /// `float` `Double`, `bool` `Bool`, `str` `String`, `bytes` or a numpy array
    /// `OctetSeq`, `list[int|float|str]` a sequence, a nested dataclass a frame and a
    /// list of them a frame sequence (nested dataclasses are registered first, unless
    /// a type of their name exists). Returns the type's name.
    fn create_type(&self, py: Python<'_>, cls: &Bound<'_, PyAny>) -> PyResult<String> {
        let dataclasses = py.import("dataclasses")?;
        if !dataclasses.call_method1("is_dataclass", (cls,))?.is_truthy()? {
            return Err(PyTypeError::new_err("create_type takes a dataclass"));
        }
        let name: String = cls.getattr("__name__")?.extract()?;
        if self.runtime.entity_type(&name).is_some() {
            return Ok(name);
        }
        let hints = py.import("typing")?.call_method1("get_type_hints", (cls,))?;
        let mut t = EntityStructureType::new(&name);
        for f in dataclasses.call_method1("fields", (cls,))?.try_iter()? {
            let field: String = f?.getattr("name")?.extract()?;
            let hint = hints.get_item(&field)?;
            let (sort, element) = self.sort_of(py, &name, &field, &hint)?;
            t = match (sort, element) {
                (esgm_core::ValueSort::EntityFrame, Some(e)) => t.frame(&field, e),
                (esgm_core::ValueSort::EntityFrameSeq, Some(e)) => t.frame_seq(&field, e),
                (sort, _) => t.attr(&field, sort),
            };
        }
        self.register(py, t)?;
        Ok(name)
    }

    /// Registers `unit` (an object with `compute(inputs, qtime)`, returning
    /// `(name, valid_time, attributes)` or `None`) as the computational unit `name`
    /// producing `type_name` from inputs of `input_types` (type names).
    fn add_comp_unit(
        &self,
        py: Python<'_>,
        name: &str,
        type_name: &str,
        input_types: Vec<String>,
        unit: Py<PyAny>,
    ) -> PyResult<()> {
        let cu = Arc::new(crate::units::PyUnit(Output::new(unit, name, type_name, &self.runtime)));
        let inputs = input_types.into_iter().map(esgm_core::esgm::InputType::Type).collect();
        let rt = Arc::clone(&self.runtime);
        let (name, type_name) = (name.to_owned(), type_name.to_owned());
        py.detach(move || on!(&*rt, e => e.add_comp_unit(&name, &type_name, inputs, cu)))
            .map_err(|e| to_py(&e))
    }

    /// Registers `sensor` (an object with `get_current_value(qtime)`, returning
    /// `(name, valid_time, attributes)` or `None`) as the sensor `name` of `type_name`.
    fn add_sensor_interface(
        &self,
        py: Python<'_>,
        name: &str,
        type_name: &str,
        sensor: Py<PyAny>,
    ) -> PyResult<()> {
        let s =
            Arc::new(crate::units::PySensor(Output::new(sensor, name, type_name, &self.runtime)));
        let rt = Arc::clone(&self.runtime);
        let (name, type_name) = (name.to_owned(), type_name.to_owned());
        py.detach(move || on!(&*rt, e => e.add_sensor_interface(&name, &type_name, s)))
            .map_err(|e| to_py(&e))
    }

    /// A computed trajectory `name`: `unit` runs on every update of `inputs`; `policy`
    /// as a primitive trajectory's.
    #[pyo3(signature = (name, unit, inputs, policy=None))]
    fn create_computed_entity_trajectory_structure(
        &self,
        py: Python<'_>,
        name: &str,
        unit: &str,
        inputs: Vec<String>,
        policy: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Trajectory> {
        self.create(py, TrajectorySpec::computed(name, unit, inputs), policy)
    }

    /// A sampled trajectory `name` (the seed's signature): `sensor` read every
    /// `sample_period` ns from `start` to `end` (0: no bound), with the largest add
    /// `delay` (0: any), keeping `cache_size` samples (0: all); `policy` changes any
    /// other setting, as a primitive trajectory's.
    #[pyo3(signature = (name, sensor, sample_period, start=0, end=0, delay=0, cache_size=0, policy=None))]
    #[allow(clippy::too_many_arguments, reason = "the seed's operation, argument for argument")]
    fn create_entity_trajectory_structure(
        &self,
        py: Python<'_>,
        name: &str,
        sensor: &str,
        sample_period: i64,
        start: i64,
        end: i64,
        delay: i64,
        cache_size: i64,
        policy: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Trajectory> {
        let illegal = |e: esgm_core::PolicyError| to_py(&esgm_core::esgm::CreateError::from(e));
        let mut spec = TrajectorySpec::sampled(name, sensor, sample_period)
            .map_err(illegal)?
            .between(start, end);
        spec.policy =
            esgm_core::FluentStreamPolicy::sampled(start, end, sample_period, delay, cache_size)
                .map_err(illegal)?;
        self.create(py, spec, policy)
    }

    /// Waits until every worker of the system has processed what it was given, at most
    /// `timeout` seconds.
    #[pyo3(signature = (timeout=10.0))]
    fn flush(&self, py: Python<'_>, timeout: f64) -> PyResult<()> {
        if !(timeout.is_finite() && timeout >= 0.0) {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "timeout {timeout} is not a time"
            )));
        }
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs_f64(timeout);
        let rt = Arc::clone(&self.runtime);
        py.detach(move || on!(&*rt, e => e.flush(deadline))).map_err(|e| to_py(&e))
    }

    /// The system's statistics (E7): every trajectory's listing, store statistics and
    /// worker counters (a Python unit's failed calls among them).
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let rt = Arc::clone(&self.runtime);
        let stats = py.detach(move || on!(&*rt, e => e.stats())).map_err(|e| to_py(&e))?;
        json_to_py(
            py,
            &serde_json::to_value(stats).map_err(|e| PyTypeError::new_err(e.to_string()))?,
        )
    }

    /// True if the system answers.
    fn ping(&self, py: Python<'_>) -> bool {
        let rt = Arc::clone(&self.runtime);
        py.detach(move || on!(&*rt, e => e.ping()))
    }

    /// Serves this process's units and sensors, GIL released, until the system ends
    /// (its coordinator gone for `patience` seconds; returns True) or a signal's
    /// handler raises (Ctrl-C: `KeyboardInterrupt`). A worker's main loop. In process,
    /// the system ends only with this process: it serves until interrupted.
    #[pyo3(signature = (patience=0.5))]
    fn serve(&self, py: Python<'_>, patience: f64) -> PyResult<bool> {
        if !(patience.is_finite() && patience >= 0.0) {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "patience {patience} is not a time"
            )));
        }
        let patience = std::time::Duration::from_secs_f64(patience);
        let rt = Arc::clone(&self.runtime);
        let mut interrupted = None;
        let go_on = || match Python::attach(|py| py.check_signals()) {
            Ok(()) => true,
            Err(e) => {
                interrupted = Some(e);
                false
            }
        };
        let gone = py.detach(|| match &*rt {
            Runtime::Shm(e) => e.serve_while(patience, go_on),
            Runtime::Local(_) => {
                let mut go_on = go_on;
                while go_on() {
                    std::thread::sleep(std::time::Duration::from_millis(250));
                }
                false
            }
        });
        interrupted.map_or(Ok(gone), Err)
    }

    fn __repr__(&self) -> &'static str {
        match &*self.runtime {
            Runtime::Local(_) => "Esgm(in process)",
            Runtime::Shm(_) => "Esgm(connected)",
        }
    }
}

/// Joins the system of `domain` (its coordinator: `esgm up` or `esgm demo`), as the
/// process `host`. Unset, both are what a supervisor gives the workers it starts
/// (`ESGM_DOMAIN`, `ESGM_WORKER`), else the domain `esgm` and a name of its own.
#[pyfunction]
#[pyo3(signature = (domain=None, host=None))]
pub fn connect(py: Python<'_>, domain: Option<String>, host: Option<String>) -> PyResult<Esgm> {
    let mut builder = ShmEsgm::builder().host(format!("python-{}", std::process::id())).from_env();
    if let Some(domain) = domain {
        builder = builder.domain(domain);
    }
    if let Some(host) = host {
        builder = builder.host(host);
    }
    let connected = py.detach(move || builder.connect());
    let esgm = connected.map_err(|e| crate::errors::Unavailable::new_err(e.to_string()))?;
    Ok(Esgm { runtime: Arc::new(Runtime::Shm(esgm)) })
}

/// An ESGM in this process (the embedded runtime), with the library types.
#[pyfunction]
#[pyo3(name = "InProcess")]
pub fn in_process() -> Esgm {
    Esgm { runtime: Arc::new(Runtime::Local(InProcessEsgm::builder().create())) }
}
