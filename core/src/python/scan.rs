//! A scan's detections as the reader read them (`semwm._core.Scan`): the core's
//! measurements, and the `Measurement` values they stand for, made only when read.
//!
//! The reader (`reader.rs`) groups a plain batch by scan. Each scan goes to the engine
//! that made the reader (`Engine.process_and_advance`), which takes its rows as they
//! are: no `Measurement` named tuple is made and read back. Python reads a scan's
//! values only when it keeps or looks at them (a held scan, a replay, a sensor view):
//! the scan is then a sequence of the `Measurement`s the specification makes, made
//! once.

use std::sync::Arc;

use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyList, PyTuple, PyType};

use crate::mhf::measurement::Measurement;

/// A detection's Python values as given (the rest is in its core `Measurement`).
pub struct Given {
    pub time: Py<PyAny>,
    pub cls: Py<PyAny>,
    pub r: Py<PyAny>,
    pub detector: Py<PyAny>,
    /// `None` when the detection names no source (the core's `""`).
    pub source: Option<Py<PyAny>>,
    /// `None` when it has none or its pair does not trust labels.
    pub label: Option<Py<PyAny>>,
    pub clutter_rate: Py<PyAny>,
    pub time_std: Py<PyAny>,
}

/// The types a scan's values are made with: `Measurement` and `tuple.__new__`.
pub struct Makers {
    pub measurement: Py<PyType>,
    pub tuple_new: Py<PyAny>,
}

/// A scan's detections: the core's rows for `engine` and, made on first read, the
/// `Measurement` values.
#[pyclass(frozen, sequence, name = "Scan", module = "semwm._core")]
pub struct PyScan {
    pub rows: Arc<[Measurement]>,
    given: Vec<Given>,
    makers: Arc<Makers>,
    /// The engine whose class and detector indices the rows use.
    pub engine: Py<PyAny>,
    made: PyOnceLock<Py<PyList>>,
}

impl PyScan {
    pub fn new(
        rows: Vec<Measurement>,
        given: Vec<Given>,
        makers: Arc<Makers>,
        engine: Py<PyAny>,
    ) -> Self {
        PyScan {
            rows: rows.into(),
            given,
            makers,
            engine,
            made: PyOnceLock::new(),
        }
    }

    /// The scan's `Measurement` values, made once.
    pub fn values<'py>(&self, py: Python<'py>) -> PyResult<&Bound<'py, PyList>> {
        let made = self.made.get_or_try_init(py, || -> PyResult<Py<PyList>> {
            let list = PyList::empty(py);
            let none = || py.None().into_bound(py);
            for (row, given) in self.rows.iter().zip(&self.given) {
                let optional = |value: &Option<Py<PyAny>>| match value {
                    Some(value) => value.bind(py).clone(),
                    None => none(),
                };
                let sensor = match &row.sensor {
                    Some(sensor) => PyArray1::from_slice(py, sensor).into_any(),
                    None => none(),
                };
                let values: [Bound<'py, PyAny>; 11] = [
                    row.seq.into_pyobject(py)?.into_any(),
                    given.time.bind(py).clone(),
                    given.cls.bind(py).clone(),
                    PyArray1::from_slice(py, &row.z).into_any(),
                    given.r.bind(py).clone(),
                    given.detector.bind(py).clone(),
                    optional(&given.source),
                    optional(&given.label),
                    given.clutter_rate.bind(py).clone(),
                    sensor,
                    given.time_std.bind(py).clone(),
                ];
                let measurement = self
                    .makers
                    .tuple_new
                    .bind(py)
                    .call1((self.makers.measurement.bind(py), PyTuple::new(py, values)?))?;
                list.append(measurement)?;
            }
            Ok(list.unbind())
        })?;
        Ok(made.bind(py))
    }
}

#[pymethods]
impl PyScan {
    fn __len__(&self) -> usize {
        self.rows.len()
    }

    fn __getitem__<'py>(&self, index: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        self.values(index.py())?.as_any().get_item(index)
    }

    fn __iter__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(self.values(py)?.as_any().try_iter()?.into_any())
    }

    /// The core's rows, as the engine takes them: `(seq, time, class index, z, R
    /// row-major, detector index, source or "", label, clutter rate, sensor position,
    /// time std)` each (for tests: they must be what the values say).
    #[allow(clippy::type_complexity)]
    fn rows(
        &self,
    ) -> Vec<(
        u64,
        f64,
        usize,
        Vec<f64>,
        Vec<f64>,
        usize,
        String,
        Option<String>,
        f64,
        Option<Vec<f64>>,
        f64,
    )> {
        self.rows
            .iter()
            .map(|m| {
                (
                    m.seq,
                    m.time,
                    m.cls,
                    m.z.clone(),
                    m.r.to_vec(),
                    m.detector,
                    m.source.to_string(),
                    m.label.as_ref().map(|label| label.to_string()),
                    m.clutter_rate,
                    m.sensor.clone(),
                    m.time_std,
                )
            })
            .collect()
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> PyResult<bool> {
        let py = other.py();
        match other.cast::<PyScan>() {
            Ok(scan) => self.values(py)?.eq(scan.get().values(py)?),
            Err(_) => self.values(py)?.eq(other),
        }
    }

    /// Pickled as the tuple of its `Measurement`s.
    fn __reduce__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyTuple>,))> {
        let tuple_type = py.get_type::<PyTuple>().into_any();
        Ok((tuple_type, (self.values(py)?.to_tuple(),)))
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        Ok(format!("Scan({})", self.values(py)?.repr()?))
    }
}
