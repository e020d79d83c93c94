//! `esgm` for Python: the ESGM's operations with the seed's names on both runtimes
//! (`runtime`), samples as read-only mappings (`sample`), attributes converted by the
//! trajectory's type (`values`), images as numpy arrays over esgm's own memory in both
//! directions (`values::octets_array`, `images`), and the IDL's exceptions
//! (`errors`). Built with maturin (`pip install ./esgm-shm/python`).

#![deny(missing_docs)]

mod errors;
mod images;
mod policy;
mod runtime;
mod sample;
mod trajectory;
mod units;
mod values;

use pyo3::prelude::*;

/// The `esgm` module.
#[pymodule]
#[pyo3(name = "_esgm")]
fn esgm(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(runtime::connect, m)?)?;
    m.add_function(wrap_pyfunction!(runtime::in_process, m)?)?;
    m.add_class::<runtime::Esgm>()?;
    m.add_class::<trajectory::Trajectory>()?;
    m.add_class::<trajectory::Subscription>()?;
    m.add_class::<trajectory::Violations>()?;
    m.add_class::<sample::Sample>()?;
    m.add_class::<images::ImageBuffer>()?;
    m.add_class::<values::OctetsOwner>()?;
    errors::register(m)?;
    // Before the interpreter finalizes, esgm's workers stop calling Python.
    let shutdown = wrap_pyfunction!(units::shutdown, m)?;
    m.py().import("atexit")?.call_method1("register", (shutdown,))?;
    Ok(())
}
