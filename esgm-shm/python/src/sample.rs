//! A sample as Python sees it: its four times, and its attributes as a read-only
//! mapping (`sample["x"]`, `sample.keys()`, `dict(sample.items())`), converted when read,
//! from where the sample lies (a sample from another process is read in its writer's
//! shared memory, nothing decoded before an attribute is asked for). An image's pixels
//! (`image_data` beside `width`, `height` and `format`) are a read-only numpy array
//! shaped `(height, width, 3)` (rgb8) or `(height, width)` (mono8), over the writer's
//! memory: no copy.

use std::sync::Arc;

use esgm_core::library::Image;
use esgm_core::{SharedStructure, ValueSort};
use pyo3::exceptions::PyKeyError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::values::from_value;

/// One sample of a trajectory (the seed's answer to a query).
#[pyclass(frozen, module = "esgm")]
#[derive(Debug)]
pub struct Sample {
    pub(crate) structure: SharedStructure,
    pub(crate) add_time: i64,
    pub(crate) query_time: i64,
    pub(crate) lineage: Option<Arc<esgm_core::Lineage>>,
}

impl Sample {
    /// From esgm's sample.
    pub fn new(s: esgm_core::Sample) -> Self {
        Self {
            structure: s.structure,
            add_time: s.add_time,
            query_time: s.query_time,
            lineage: s.lineage,
        }
    }

    fn long(&self, name: &str) -> Option<i64> {
        self.structure.get(name).filter(|v| v.sort() == ValueSort::Long)?.as_long()
    }

    /// `(height, width[, 3])` if the structure is an image whose pixels `len` bytes fit.
    fn image_shape(&self, len: usize) -> Option<Vec<usize>> {
        let (w, h, f) = (self.long("width")?, self.long("height")?, self.long("format")?);
        let bpp = Image::bytes_per_pixel(f)?;
        let (w, h) = (usize::try_from(w).ok()?, usize::try_from(h).ok()?);
        (w.checked_mul(h)?.checked_mul(bpp)? == len)
            .then(|| if bpp == 1 { vec![h, w] } else { vec![h, w, bpp] })
    }

    fn value<'py>(&self, py: Python<'py>, key: &str) -> PyResult<Bound<'py, PyAny>> {
        let v = self
            .structure
            .get(key)
            .ok_or_else(|| PyKeyError::new_err(format!("the sample has no attribute `{key}`")))?;
        let out = from_value(py, v)?;
        if let Some(bytes) = v.as_bytes() {
            if let Some(shape) = self.image_shape(bytes.len()) {
                return out.call_method1("reshape", (shape,));
            }
        }
        Ok(out)
    }
}

#[pymethods]
impl Sample {
    /// The entity's name.
    #[getter]
    fn name(&self) -> &str {
        self.structure.name()
    }
    /// When its content is true of the world (ns).
    #[getter]
    fn valid_time(&self) -> i64 {
        self.structure.valid_time()
    }
    /// When its content was made (ns).
    #[getter]
    fn create_time(&self) -> i64 {
        self.structure.create_time()
    }
    /// When it entered the trajectory (ns).
    #[getter]
    fn add_time(&self) -> i64 {
        self.add_time
    }
    /// When the query it answers was asked (ns).
    #[getter]
    fn query_time(&self) -> i64 {
        self.query_time
    }
    /// The input structures it was made from, as a dict (`inputs`: each input's
    /// `trajectory`, `generation`, `valid_time` and `add_time`; `complete`: False for
    /// a unit, which may have read more), or None for a pushed or sampled structure.
    #[getter]
    fn lineage<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let v = serde_json::to_value(self.lineage.as_deref())
            .map_err(|e| pyo3::exceptions::PyTypeError::new_err(e.to_string()))?;
        crate::runtime::json_to_py(py, &v)
    }
    fn __getitem__<'py>(&self, py: Python<'py>, key: &str) -> PyResult<Bound<'py, PyAny>> {
        self.value(py, key)
    }
    fn __contains__(&self, key: &str) -> bool {
        self.structure.get(key).is_some()
    }
    fn __len__(&self) -> usize {
        self.structure.attribute_count()
    }
    fn __iter__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.keys(py)?.try_iter().map(Bound::into_any)
    }
    /// The attribute names, in the type's order.
    fn keys<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        PyList::new(py, self.structure.attributes().map(|(name, _)| name))
    }
    /// `(name, value)` pairs.
    fn items<'py>(&self, py: Python<'py>) -> PyResult<Vec<(String, Bound<'py, PyAny>)>> {
        self.structure
            .attributes()
            .map(|(name, _)| Ok((name.to_owned(), self.value(py, name)?)))
            .collect()
    }
    /// The attributes as a `dict`.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (name, _) in self.structure.attributes() {
            d.set_item(name, self.value(py, name)?)?;
        }
        Ok(d)
    }
    /// The sample as an instance of `cls` (a dataclass whose fields are attributes):
    /// `cls(**sample.to_dict())`, fields it lacks left out.
    fn to<'py>(&self, py: Python<'py>, cls: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let fields = py.import("dataclasses")?.call_method1("fields", (cls,))?;
        let kwargs = PyDict::new(py);
        for f in fields.try_iter()? {
            let name: String = f?.getattr("name")?.extract()?;
            if self.structure.get(&name).is_some() {
                kwargs.set_item(&name, self.value(py, &name)?)?;
            }
        }
        cls.call((), Some(&kwargs))
    }
    fn __repr__(&self) -> String {
        let names: Vec<&str> = self.structure.attributes().map(|(name, _)| name).collect();
        format!(
            "Sample(name={:?}, valid_time={}, add_time={}, attributes=[{}])",
            self.structure.name(),
            self.structure.valid_time(),
            self.add_time,
            names.join(", ")
        )
    }
}
