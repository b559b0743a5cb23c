//! The published world of a scan as the core found it (`WorldModel._published`: id ->
//! version), its Python values made only when someone reads them.
//!
//! Every scan publishes: each object shown gets its id (`WorldModel._publish`). In the
//! common scan nobody reads the table before the next scan replaces it; the next
//! `Engine.publish` needs only its lineages, and queries read the ids (`_ids`) and the
//! state. So the table holds plain rows, and the `{id: VersionRef}` dict it stands for
//! is made once, on the first read of a value (an object lost, the knowledge changed, a
//! snapshot). It reads as that dict: a `Mapping`.

use std::sync::Arc;

use pyo3::exceptions::PyKeyError;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyIterator, PyString};

use crate::python::engine::PyVersionRef;

/// One object of the published world: its id, lineage, the key and serial of its
/// version, and its class's index.
#[derive(Clone, Copy, Debug)]
pub struct Row {
    pub id: i64,
    pub lineage: u64,
    pub key: u64,
    pub serial: u64,
    pub cls: usize,
}

/// `{id: VersionRef}` of the objects shown, in the published world's order.
#[pyclass(frozen, mapping, name = "Published", module = "semwm._core")]
pub struct PyPublished {
    rows: Vec<Row>,
    /// the class names by index (the engine's list, shared)
    names: Arc<[Py<PyString>]>,
    /// the `CoreState` holding the versions
    state: Py<PyAny>,
    made: PyOnceLock<Py<PyDict>>,
}

impl PyPublished {
    pub fn new(rows: Vec<Row>, names: Arc<[Py<PyString>]>, state: Py<PyAny>) -> Self {
        PyPublished {
            rows,
            names,
            state,
            made: PyOnceLock::new(),
        }
    }

    /// The lineages shown, in order (no Python value made).
    pub fn lineages(&self) -> impl Iterator<Item = u64> + '_ {
        self.rows.iter().map(|row| row.lineage)
    }

    /// The dict this table stands for, made on first use.
    fn dict<'py>(&self, py: Python<'py>) -> PyResult<&Bound<'py, PyDict>> {
        let made = self.made.get_or_try_init(py, || -> PyResult<Py<PyDict>> {
            let dict = PyDict::new(py);
            for row in &self.rows {
                let reference = PyVersionRef::new(
                    row.lineage,
                    self.names[row.cls].clone_ref(py),
                    row.key,
                    row.serial,
                    self.state.clone_ref(py),
                );
                dict.set_item(row.id, Bound::new(py, reference)?)?;
            }
            Ok(dict.unbind())
        })?;
        Ok(made.bind(py))
    }
}

#[pymethods]
impl PyPublished {
    fn __len__(&self) -> usize {
        self.rows.len()
    }

    fn __contains__(&self, key: &Bound<'_, PyAny>) -> bool {
        match key.extract::<i64>() {
            Ok(id) => self.rows.iter().any(|row| row.id == id),
            Err(_) => false,
        }
    }

    fn __getitem__<'py>(&self, key: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        self.dict(key.py())?
            .get_item(key)?
            .ok_or_else(|| PyKeyError::new_err(key.clone().unbind()))
    }

    fn __iter__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyIterator>> {
        let ids: Vec<i64> = self.rows.iter().map(|row| row.id).collect();
        PyIterator::from_object(&ids.into_pyobject(py)?)
    }

    #[pyo3(signature = (key, default=None))]
    fn get<'py>(
        &self,
        key: &Bound<'py, PyAny>,
        default: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Option<Bound<'py, PyAny>>> {
        Ok(self.dict(key.py())?.get_item(key)?.or(default))
    }

    fn keys<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.dict(py)?.call_method0("keys")
    }

    fn values<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.dict(py)?.call_method0("values")
    }

    fn items<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.dict(py)?.call_method0("items")
    }

    /// The lineages shown, in order, without making their versions' values.
    #[pyo3(name = "lineages")]
    fn py_lineages(&self) -> Vec<u64> {
        self.lineages().collect()
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> PyResult<bool> {
        let py = other.py();
        match other.cast::<PyPublished>() {
            Ok(table) => self.dict(py)?.eq(table.get().dict(py)?),
            Err(_) => self.dict(py)?.eq(other),
        }
    }

    /// Pickled as the dict it stands for (whose `VersionRef`s pickle as `Track`s).
    fn __reduce__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyDict>,))> {
        let dict_type = py.get_type::<PyDict>().into_any();
        Ok((dict_type, (self.dict(py)?.clone(),)))
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        Ok(format!("Published({})", self.dict(py)?.repr()?))
    }
}
