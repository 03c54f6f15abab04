//! The 6-UPS's forward dynamics from Python through PyO3 (a measurement; see Cargo.toml).
use pyo3::prelude::*;
use numpy::{PyArray1, PyReadonlyArray1};
use rbss_runtime::{Baumgarte, Data, Model};
use stewart_6ups::Stewart6Ups;

#[pyclass(unsendable)]
struct Robot {
    model: Model<Stewart6Ups, 24, 18>,
    data: Box<Data<24, 18>>,
}

#[pymethods]
impl Robot {
    #[new]
    fn new() -> Self {
        let model = Model::new(Stewart6Ups::default());
        let data = Box::new(Data::new(&model));
        Self { model, data }
    }

    /// (xddot, lambda) under u.
    #[allow(clippy::type_complexity)]
    fn forward_dynamics<'py>(
        &mut self,
        py: Python<'py>,
        x: PyReadonlyArray1<'py, f64>,
        xdot: PyReadonlyArray1<'py, f64>,
        u: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>)> {
        let (x, xdot, u) = (x.as_slice()?, xdot.as_slice()?, u.as_slice()?);
        if x.len() != 24 || xdot.len() != 24 {
            return Err(pyo3::exceptions::PyValueError::new_err("x, xdot: 24 values"));
        }
        self.data.x.copy_from_slice(x);
        self.data.xdot.copy_from_slice(xdot);
        rbss_runtime::forward_dynamics(&self.model, &mut self.data, u, None, Baumgarte::NONE)
            .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
        Ok((
            PyArray1::from_slice(py, &self.data.xddot),
            PyArray1::from_slice(py, &self.data.lambda),
        ))
    }
}

#[pymodule]
fn rbss_pyo3_probe(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Robot>()
}
