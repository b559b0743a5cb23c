//! `semwm._core.Engine` and `semwm._core.State`: the whole scan in the core, the state
//! kept in the core between scans (`crate::mhf::filter`). `semwm/mhf/core_engine.py`
//! builds the knowledge's tables with the Python engine's own code and wraps both.
//!
//! A scan's detections cross as one list of plain tuples, a state stays in the core;
//! Python reads a state's clusters and versions (for queries, the tests and the
//! hypotheses view) through `State`'s methods, which copy only what is asked for. The
//! published world crosses as `VersionRef`s made here (`Engine.current`,
//! `Engine.publish`, which also gives publishing's common case).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use litemap::LiteMap;
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyOverflowError, PyValueError};
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString, PyTuple};

use crate::error::KernelError;
use crate::mhf::existence::View;
use crate::mhf::filter::Filter;
use crate::mhf::hypotheses::{Cluster, Hypothesis, KeyMap, KeySet};
use crate::mhf::measurement::{Measurement, SensorView};
use crate::mhf::rates::Name;
use crate::mhf::state::{next_serial, Entry, FilterState, Key, State, Version};
use crate::mhf::tables::{Appearance, ClassSpec, DetectorSpec, LeaveRelation, Tables};
use crate::python::published::{PyPublished, Row};
use crate::python::rates::PyObservedRates;
use crate::python::scan::PyScan;
use crate::python::{run, PyClassFilter};
use crate::world::Summaries;

fn item<'py, T: FromPyObjectOwned<'py>>(dict: &Bound<'py, PyDict>, key: &str) -> PyResult<T> {
    let value = dict
        .get_item(key)?
        .ok_or_else(|| PyValueError::new_err(format!("tables: missing {key:?}")))?;
    value.extract::<T>().map_err(|error| {
        let error: PyErr = error.into();
        PyValueError::new_err(format!("tables: {key:?} has the wrong type: {error}"))
    })
}

fn items<'py>(dict: &Bound<'py, PyDict>, key: &str) -> PyResult<Vec<Bound<'py, PyDict>>> {
    let list: Bound<'py, PyList> = item(dict, key)?;
    list.iter()
        .map(|entry| {
            entry.cast_into::<PyDict>().map_err(|_| {
                PyValueError::new_err(format!("tables: every entry of {key:?} must be a dict"))
            })
        })
        .collect()
}

fn class_spec(class: &Bound<'_, PyDict>) -> PyResult<ClassSpec> {
    let filter: PyRef<'_, PyClassFilter> = item(class, "filter")?;
    let leave_relations = items(class, "leave_relations")?
        .iter()
        .map(|r| {
            Ok(LeaveRelation {
                target: item(r, "target")?,
                max_distance: item(r, "max_distance")?,
                frequency: item(r, "frequency")?,
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    let appearance = items(class, "appearance")?
        .iter()
        .map(|r| {
            Ok(Appearance {
                covered: item(r, "covered")?,
                frequency: item(r, "frequency")?,
                max_distance: item(r, "max_distance")?,
                log_num: item(r, "log_num")?,
                known: item(r, "known")?,
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    Ok(ClassSpec {
        name: Name::from(item::<String>(class, "name")?),
        filter: filter.tables.clone(),
        initial_covariance: item(class, "initial_covariance")?,
        initial_mode_probabilities: item(class, "initial_mode_probabilities")?,
        detection_frequency: item(class, "detection_frequency")?,
        detection_probability: item(class, "detection_probability")?,
        leave_frequency: item(class, "leave_frequency")?,
        new_frequency: item(class, "new_frequency")?,
        max_position_variance: item(class, "max_position_variance")?,
        max_time_without_update: item(class, "max_time_without_update")?,
        region_margin: item(class, "region_margin")?,
        region_cap: item(class, "region_cap")?,
        leave_relations,
        appearance,
        can_appear: item(class, "can_appear")?,
        kick_probability: item(class, "kick_probability")?,
        confidence_decay: item(class, "confidence_decay")?,
        looking_decay: item(class, "looking_decay")?,
        confidence_decay_distance: item(class, "confidence_decay_distance")?,
    })
}

fn detector_spec(detector: &Bound<'_, PyDict>) -> PyResult<DetectorSpec> {
    Ok(DetectorSpec {
        name: Name::from(item::<String>(detector, "name")?),
        clutter_log_density: item(detector, "clutter_log_density")?,
        likelihood: item(detector, "likelihood")?,
        range: item(detector, "range")?,
        fixed: item(detector, "fixed")?,
        position: item(detector, "position")?,
        confidence: item(detector, "confidence")?,
    })
}

fn tables_from(tables: &Bound<'_, PyDict>) -> PyResult<Tables> {
    let classes = items(tables, "classes")?
        .iter()
        .map(class_spec)
        .collect::<PyResult<Vec<_>>>()?;
    let detectors = items(tables, "detectors")?
        .iter()
        .map(detector_spec)
        .collect::<PyResult<Vec<_>>>()?;
    Ok(Tables {
        dim: item(tables, "dim")?,
        classes,
        detectors,
        default_detector: item(tables, "default_detector")?,
        mht: item(tables, "mht")?,
        missed_detections: item(tables, "missed_detections")?,
        observed_rates: item(tables, "observed_rates")?,
        ratio: item(tables, "ratio")?,
        max_hypotheses: item(tables, "max_hypotheses")?,
        merge_distance: item(tables, "merge_distance")?,
        removal_existence: item(tables, "removal_existence")?,
        region: item(tables, "region")?,
        gate: item(tables, "gate")?,
        gate_quantile: item(tables, "gate_quantile")?,
        label_gate: item(tables, "label_gate")?,
        log_label_error: item(tables, "log_label_error")?,
        log_volume: item(tables, "log_volume")?,
        subtree: item(tables, "subtree")?,
        depth: item(tables, "depth")?,
        appear_mask: item(tables, "appear_mask")?,
        compatible: item(tables, "compatible")?,
        class_likelihood: item(tables, "class_likelihood")?,
        most_specific: item(tables, "most_specific")?,
        min_existence: item(tables, "min_existence")?,
    })
}

fn to_py_err(error: KernelError) -> PyErr {
    PyValueError::new_err(error.to_string())
}

/// A sensor view: time, source (`""`), position (x, y), heading, range, half opening,
/// lineages looked at, detector index.
type ViewRow = (
    f64,
    String,
    (f64, f64),
    f64,
    Option<f64>,
    Option<f64>,
    Vec<u64>,
    Option<usize>,
);

/// A version as it crosses: (key, lineage, class index, label), (modes, state size, x
/// flat, P flat, mu), (time, last seen, created, rate), (class probabilities, sources,
/// existence).
type VersionRow = (
    (u64, u64, usize, Option<String>),
    (usize, usize, Vec<f64>, Vec<f64>, Vec<f64>),
    (f64, f64, f64, f64),
    (Vec<f64>, Vec<String>, f64),
);

/// A cluster as it crosses: its hypotheses (log weight, keys, rate).
type ClusterRow = Vec<(f64, Vec<u64>, f64)>;

fn sensor_view(row: ViewRow) -> SensorView {
    let (time, source, (x, y), heading, range, half_angle, looking_at, detector) = row;
    SensorView {
        time,
        source: Name::from(source),
        view: View {
            position: [x, y],
            heading,
            range,
            half_angle,
        },
        looking_at,
        detector,
    }
}

/// The confidence book (`semwm.confidence.ConfidenceBook`) kept in the core.
#[pyclass(frozen, name = "Book", module = "semwm._core")]
pub struct PyBook {
    book: Arc<crate::confidence::Book>,
}

/// A lineage's confidence value and since when; a source's pose; a source's last scan.
type BookRows = (
    Vec<(u64, f64, f64)>,
    Vec<(String, f64, f64)>,
    Vec<(String, f64)>,
);

#[pymethods]
impl PyBook {
    #[new]
    fn new() -> Self {
        PyBook {
            book: Arc::new(crate::confidence::Book::default()),
        }
    }

    /// A book from plain rows (`state`'s layout).
    #[staticmethod]
    fn of(
        values: Vec<(u64, f64, f64)>,
        poses: Vec<(String, f64, f64)>,
        scans: Vec<(String, f64)>,
    ) -> Self {
        let book = crate::confidence::Book {
            values: values.into_iter().map(|(l, v, t)| (l, (v, t))).collect(),
            poses: poses
                .into_iter()
                .map(|(s, x, y)| (Name::from(s), (x, y)))
                .collect(),
            scans: scans.into_iter().map(|(s, t)| (Name::from(s), t)).collect(),
        };
        PyBook {
            book: Arc::new(book),
        }
    }

    /// The book as plain rows: values (lineage, value, since) in lineage order, poses,
    /// scans.
    fn state(&self) -> BookRows {
        let book = &self.book;
        let mut values: Vec<(u64, f64, f64)> =
            book.values.iter().map(|(l, (v, t))| (*l, *v, *t)).collect();
        values.sort_by_key(|row| row.0);
        (
            values,
            book.poses
                .iter()
                .map(|(s, (x, y))| (s.to_string(), *x, *y))
                .collect(),
            book.scans
                .iter()
                .map(|(s, t)| (s.to_string(), *t))
                .collect(),
        )
    }

    /// A lineage's (value, since), if the book holds it.
    fn entry(&self, lineage: u64) -> Option<(f64, f64)> {
        self.book.values.get(&lineage).copied()
    }
}

/// The filter of one knowledge base, its whole scan in the core.
#[pyclass(frozen, name = "Engine", module = "semwm._core")]
pub struct PyEngine {
    filter: Arc<Filter>,
    classes: HashMap<String, usize>,
    detectors: HashMap<String, usize>,
    /// the class names as Python strings, by index (each `VersionRef` shares its class's,
    /// each scan's published table the list)
    names: Arc<[Py<PyString>]>,
    /// each class's mode names as Python strings, by index: `None` for a filter of one
    /// mode (whose objects show no mode probabilities)
    mode_names: Vec<Option<Vec<Py<PyString>>>>,
    /// the versions' summaries the last published world used (`world::Summaries`)
    summaries: Arc<Mutex<Summaries>>,
}

/// One object of `Engine.world_at`: `(lineage, existence, created, position, fields,
/// confidence)`, `fields` a `WorldObject`'s.
type WorldRow<'py> = (
    u64,
    f64,
    f64,
    Bound<'py, PyTuple>,
    Bound<'py, PyDict>,
    Option<f64>,
);

/// What `Engine.world_at` computes of one object with the GIL released: its marginal,
/// its id (`None`: tentative), its prediction (position, covariance, velocity, mode
/// probabilities), its version and its confidence carried to the query's time.
type WorldValues = (
    crate::world::Marginal,
    Option<i64>,
    Vec<f64>,
    Vec<f64>,
    Option<Vec<f64>>,
    Vec<f64>,
    Arc<Version>,
    Option<f64>,
);

/// A version of a core state, named without making its Python value
/// (`semwm.mhf.core_engine.VersionRef`): the published world of every scan names every
/// object shown, so one is made per object and scan, here rather than in Python.
/// `state` is the `CoreState` (Python) that holds the version.
#[pyclass(frozen, get_all, name = "VersionRef", module = "semwm._core")]
pub struct PyVersionRef {
    lineage: u64,
    cls: Py<PyString>,
    key: u64,
    serial: u64,
    state: Py<PyAny>,
}

#[pymethods]
impl PyVersionRef {
    #[new]
    pub(crate) fn new(
        lineage: u64,
        cls: Py<PyString>,
        key: u64,
        serial: u64,
        state: Py<PyAny>,
    ) -> Self {
        PyVersionRef {
            lineage,
            cls,
            key,
            serial,
            state,
        }
    }

    /// Pickled as the version's Python value, a `Track` (a snapshot holds the published
    /// world; the core state it names lives in this process only, as `CoreState`
    /// pickles as the specification's `MHFState`): `semwm.mhf.core_engine.track_of`.
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyAny>,))> {
        let module = slf.py().import("semwm.mhf.core_engine")?;
        let track = module.getattr("track_of")?.call1((slf,))?;
        Ok((module.getattr("unpickled_track")?, (track,)))
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!(
            "VersionRef(lineage={}, cls={:?}, key={}, serial={})",
            self.lineage,
            self.cls.bind(py).to_string(),
            self.key,
            self.serial
        )
    }
}

/// The lineage of a published object: a `VersionRef`'s, or any value's `lineage`.
fn lineage_of(value: &Bound<'_, PyAny>) -> PyResult<u64> {
    match value.cast::<PyVersionRef>() {
        Ok(reference) => Ok(reference.get().lineage),
        Err(_) => value.getattr("lineage")?.extract(),
    }
}

/// The lineages of the published world (`WorldModel._published`): a `Published`
/// table's rows, or a dict's values' lineages.
fn published_lineages(published: &Bound<'_, PyAny>) -> PyResult<Vec<u64>> {
    if let Ok(table) = published.cast::<PyPublished>() {
        return Ok(table.get().lineages().collect());
    }
    let dict = published.cast::<PyDict>().map_err(|_| {
        PyValueError::new_err("published: a dict or a Published table of the shown objects")
    })?;
    dict.values()
        .iter()
        .map(|value| lineage_of(&value))
        .collect()
}

/// An object shown: (lineage, key, class, serial).
type ShownRow = (u64, u64, usize, u64);

/// `world::current` of `held` as rows, with the engine's cache of version summaries.
fn shown_rows(
    held: &State,
    filter: &Filter,
    summaries: &Mutex<Summaries>,
    shown: &KeySet<u64>,
    ids: &KeyMap<u64, i64>,
) -> Vec<ShownRow> {
    // a panic while it was held leaves summaries of versions, each whole
    let mut cache = summaries
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    crate::world::current(held, &filter.tables, shown, ids, &mut cache)
        .into_iter()
        .map(|(lineage, key)| {
            let entry = &held.tracks[&key];
            (lineage, key, entry.version.cls, entry.serial)
        })
        .collect()
}

impl PyEngine {
    /// Every lineage `state` (a `CoreState`) holds; empty if it is not one.
    fn lineages_of(&self, state: &Bound<'_, PyAny>) -> KeySet<u64> {
        let core = state
            .getattr("core")
            .and_then(|core| core.extract::<PyRef<'_, PyState>>().map_err(PyErr::from));
        match core {
            Ok(core) => core
                .state
                .tracks
                .values()
                .map(|e| e.version.lineage)
                .collect(),
            Err(_) => KeySet::default(),
        }
    }

    /// `publish` once `rows` (`current_rows` of `state`, given `before`, the lineages
    /// published, and `table`, the ids) are known.
    #[allow(clippy::too_many_arguments)]
    fn published_after<'py>(
        &self,
        state: &Bound<'py, PyAny>,
        rows: &[ShownRow],
        table: KeyMap<u64, i64>,
        before: &KeySet<u64>,
        ids: &Bound<'py, PyDict>,
        lost: bool,
        next_id: i64,
        waiting: &[(i64, u64)],
    ) -> PyResult<(Option<Bound<'py, PyDict>>, Option<Unchanged<'py>>)> {
        let py = state.py();
        let showing: KeySet<u64> = rows.iter().map(|row| row.0).collect();
        // a lineage with an id that is not shown: the one of an id waiting for it, still
        // held by the state (the general path drops the ids of lineages gone)
        let mut alive: Option<KeySet<u64>> = None;
        let mut unshown_waits = |lineage: u64, id: i64| {
            waiting.contains(&(id, lineage))
                && alive
                    .get_or_insert_with(|| self.lineages_of(state))
                    .contains(&lineage)
        };
        let still_waiting = || {
            rows.iter().all(|&(lineage, ..)| {
                table.get(&lineage).is_some_and(|id| {
                    waiting
                        .iter()
                        .all(|&(lost_id, lost_lineage)| lost_id != *id && lost_lineage != lineage)
                })
            })
        };
        let left = lost
            || table
                .iter()
                .any(|(&lineage, &id)| !showing.contains(&lineage) && !unshown_waits(lineage, id))
            || before.iter().any(|lineage| !showing.contains(lineage))
            || (!waiting.is_empty() && !still_waiting());
        if left {
            return Ok((Some(self.current_refs(state, rows)?), None));
        }
        let (mut table, mut next_id) = (table, next_id);
        let mut copied: Option<Bound<'py, PyDict>> = None;
        for &(lineage, ..) in rows {
            if table.contains_key(&lineage) {
                continue;
            }
            // a new table: one a query cached must not change
            let fresh = match &copied {
                Some(dict) => dict,
                None => copied.insert(ids.copy()?),
            };
            fresh.set_item(lineage, next_id)?;
            table.insert(lineage, next_id);
            next_id += 1;
        }
        let shown = rows
            .iter()
            .map(|&(lineage, key, cls, serial)| Row {
                id: table[&lineage],
                lineage,
                key,
                serial,
                cls,
            })
            .collect();
        let names = self.names.clone();
        let shown = Bound::new(py, PyPublished::new(shown, names, state.clone().unbind()))?;
        Ok((
            None,
            Some((copied.unwrap_or_else(|| ids.clone()), shown, next_id)),
        ))
    }

    /// A scan's `Measurement` named tuples as the core's measurements (see
    /// `process_measurements`).
    fn read_measurements(&self, measurements: &Bound<'_, PyList>) -> PyResult<Vec<Measurement>> {
        let tables = &self.filter.tables;
        let d = tables.dim;
        let mut scan = Vec::with_capacity(measurements.len());
        // a batch's detections share their class's noise array and usually their source:
        // read each once (by identity; names by value)
        let mut last_r: Option<(Bound<'_, PyAny>, Arc<[f64]>)> = None;
        let mut last_source: Option<Name> = None;
        for (j, item) in measurements.iter().enumerate() {
            let not_one = |error: PyErr| {
                PyValueError::new_err(format!("measurements[{j}]: not a Measurement: {error}"))
            };
            let fields = item.cast::<PyTuple>().map_err(|e| not_one(e.into()))?;
            if fields.len() != 11 {
                return Err(PyValueError::new_err(format!(
                    "measurements[{j}]: not a Measurement: {} fields, not 11",
                    fields.len()
                )));
            }
            let field = |i: usize| fields.get_item(i);
            let seq: u64 = field(0)?.extract().map_err(not_one)?;
            let time: f64 = field(1)?.extract().map_err(not_one)?;
            let cls = index_of(&self.classes, &field(2)?, "class", j)?;
            let detector = index_of(&self.detectors, &field(5)?, "detector", j)?;
            let z = float_values(&field(3)?).map_err(not_one)?;
            let r_object = field(4)?;
            let r = match &last_r {
                Some((object, values)) if object.is(&r_object) => values.clone(),
                _ => {
                    let values: Arc<[f64]> = float_values(&r_object).map_err(not_one)?.into();
                    last_r = Some((r_object, values.clone()));
                    values
                }
            };
            if z.len() != d || r.len() != d * d {
                return Err(PyValueError::new_err(format!(
                    "measurements[{j}]: expected z of {d} and R of {} values",
                    d * d
                )));
            }
            let source = field(6)?;
            let source = if source.is_none() {
                ""
            } else {
                source
                    .cast::<PyString>()
                    .map_err(|e| not_one(e.into()))?
                    .to_str()?
            };
            let source = match &last_source {
                Some(name) if &**name == source => name.clone(),
                _ => {
                    let name = Name::from(source);
                    last_source = Some(name.clone());
                    name
                }
            };
            let label: Option<String> = field(7)?.extract().map_err(not_one)?;
            let clutter_rate: f64 = field(8)?.extract().map_err(not_one)?;
            let sensor = field(9)?;
            let sensor = if sensor.is_none() {
                None
            } else {
                Some(float_values(&sensor).map_err(not_one)?)
            };
            let time_std: f64 = field(10)?.extract().map_err(not_one)?;
            scan.push(Measurement {
                seq,
                time,
                cls,
                z,
                r,
                detector,
                source,
                label: label.map(Name::from),
                clutter_rate,
                sensor,
                time_std,
            });
        }
        Ok(scan)
    }

    /// `world::current` of `state` (a `CoreState`): (lineage, key, class, serial) of
    /// each object shown, in the specification's order; `published` the objects shown
    /// now (`WorldModel._published`), `ids` their ids.
    fn current_rows(
        &self,
        state: &Bound<'_, PyAny>,
        shown: KeySet<u64>,
        ids: &KeyMap<u64, i64>,
    ) -> PyResult<Vec<ShownRow>> {
        let core: PyRef<'_, PyState> = state.getattr("core")?.extract()?;
        let filter = self.filter.clone();
        let held = core.state.clone();
        let summaries = self.summaries.clone();
        run(state.py(), "Engine.current", move || {
            Ok(shown_rows(&held, &filter, &summaries, &shown, ids))
        })
    }

    /// `rows` (`current_rows`) as `{lineage: VersionRef}`.
    fn current_refs<'py>(
        &self,
        state: &Bound<'py, PyAny>,
        rows: &[(u64, u64, usize, u64)],
    ) -> PyResult<Bound<'py, PyDict>> {
        let py = state.py();
        let current = PyDict::new(py);
        for &(lineage, key, cls, serial) in rows {
            let reference = PyVersionRef {
                lineage,
                cls: self.class_name(py, cls)?,
                key,
                serial,
                state: state.clone().unbind(),
            };
            current.set_item(lineage, Bound::new(py, reference)?)?;
        }
        Ok(current)
    }

    fn class_name(&self, py: Python<'_>, cls: usize) -> PyResult<Py<PyString>> {
        self.names
            .get(cls)
            .map(|name| name.clone_ref(py))
            .ok_or_else(|| PyValueError::new_err(format!("Engine.current: no class {cls}")))
    }
}

/// The index of measurement `j`'s class or detector name (`what`) in `names`.
fn index_of(
    names: &HashMap<String, usize>,
    name: &Bound<'_, PyAny>,
    what: &str,
    j: usize,
) -> PyResult<usize> {
    let name = name.cast::<PyString>().map_err(|error| {
        let error: PyErr = error.into();
        PyValueError::new_err(format!("measurements[{j}]: not a Measurement: {error}"))
    })?;
    let name = name.to_str()?;
    names
        .get(name)
        .copied()
        .ok_or_else(|| PyValueError::new_err(format!("measurements[{j}]: unknown {what} {name:?}")))
}

/// A float64 array's values in row-major order (copied: no borrow is held, as the
/// values are read at once).
fn float_values(array: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
    fn copied(error: impl std::fmt::Display) -> PyErr {
        PyValueError::new_err(format!("array not readable: {error}"))
    }
    if let Ok(vector) = array.cast::<PyArray1<f64>>() {
        return if vector.is_c_contiguous() {
            vector.to_vec().map_err(copied)
        } else {
            Ok(vector.to_owned_array().iter().copied().collect())
        };
    }
    if let Ok(matrix) = array.cast::<PyArray2<f64>>() {
        return if matrix.is_c_contiguous() {
            matrix.to_vec().map_err(copied)
        } else {
            Ok(matrix.to_owned_array().iter().copied().collect())
        };
    }
    match array.cast::<PyUntypedArray>() {
        Ok(other) => Err(PyValueError::new_err(format!(
            "expected a float64 array of 1 or 2 dimensions, got {} of {} dimensions",
            other.dtype(),
            other.ndim()
        ))),
        Err(_) => Err(PyValueError::new_err(format!(
            "expected a float64 array, got {}",
            array.get_type().name()?
        ))),
    }
}

/// `WorldModel._publish_unchanged`'s tables: `(ids, published, next_id)`.
/// A scan's rows for `engine`: a `Scan` the reader read for it as they are; a list of
/// `Measurement`s (or another engine's `Scan`, by its values) read here.
fn scan_rows(
    engine: &Bound<'_, PyEngine>,
    measurements: &Bound<'_, PyAny>,
) -> PyResult<Arc<[Measurement]>> {
    if let Ok(scan) = measurements.cast::<PyScan>() {
        let scan = scan.get();
        if scan.engine.bind(engine.py()).is(engine) {
            return Ok(scan.rows.clone());
        }
        return Ok(engine
            .get()
            .read_measurements(scan.values(engine.py())?)?
            .into());
    }
    let list = measurements.cast::<PyList>().map_err(|_| {
        PyValueError::new_err("measurements: a list of Measurement values or a Scan")
    })?;
    Ok(engine.get().read_measurements(list)?.into())
}

type Unchanged<'py> = (Bound<'py, PyDict>, Bound<'py, PyPublished>, i64);

/// `Engine.process_and_publish`'s answer: the state and book after the scan, and
/// `publish`'s `(current, unchanged)`.
type ScanPublished<'py> = (
    Bound<'py, PyAny>,
    PyBook,
    Option<Bound<'py, PyDict>>,
    Option<Unchanged<'py>>,
);

fn id_table(ids: &Bound<'_, PyDict>) -> PyResult<KeyMap<u64, i64>> {
    let mut table: KeyMap<u64, i64> = KeyMap::default();
    table.reserve(ids.len());
    for (lineage, id) in ids.iter() {
        table.insert(lineage.extract()?, id.extract()?);
    }
    Ok(table)
}

#[pymethods]
impl PyEngine {
    /// The engine of `tables` (a dict: `semwm/mhf/core_engine.py: tables`).
    #[new]
    fn new(tables: &Bound<'_, PyDict>) -> PyResult<Self> {
        let tables_py = tables;
        let tables = tables_from(tables)?;
        let filter = Filter::new(tables).map_err(to_py_err)?;
        let classes = filter
            .tables
            .classes
            .iter()
            .enumerate()
            .map(|(i, c)| (c.name.to_string(), i))
            .collect();
        let detectors = filter
            .tables
            .detectors
            .iter()
            .enumerate()
            .map(|(i, d)| (d.name.to_string(), i))
            .collect();
        let names = filter
            .tables
            .classes
            .iter()
            .map(|c| PyString::new(tables_py.py(), &c.name).unbind())
            .collect();
        // display values, not the filter's tables: each class's mode names when it has
        // several (`semwm/mhf/core_engine.py: tables`)
        let mode_names = items(tables_py, "classes")?
            .iter()
            .map(|class| {
                let names: Option<Vec<String>> = match class.get_item("mode_names")? {
                    None => None,
                    Some(names) => names.extract()?,
                };
                Ok(names.map(|names| {
                    names
                        .iter()
                        .map(|name| PyString::new(tables_py.py(), name).unbind())
                        .collect()
                }))
            })
            .collect::<PyResult<Vec<_>>>()?;
        Ok(PyEngine {
            filter: Arc::new(filter),
            classes,
            detectors,
            names,
            mode_names,
            summaries: Arc::default(),
        })
    }

    /// The published world of `state`, a `CoreState` (`WorldModel._current`):
    /// `{lineage: VersionRef}` of each object shown, in the specification's order;
    /// `published` the objects shown now by id (`WorldModel._published`: a dict or a
    /// `Published`), `ids` their ids (`WorldModel._ids`, lineage -> id).
    fn current<'py>(
        &self,
        state: &Bound<'py, PyAny>,
        published: &Bound<'py, PyAny>,
        ids: &Bound<'py, PyDict>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let shown = published_lineages(published)?.into_iter().collect();
        let rows = self.current_rows(state, shown, &id_table(ids)?)?;
        self.current_refs(state, &rows)
    }

    /// `WorldModel._may_return` of version `key` of `state` (a `CoreState`'s core), an
    /// object lost from the published world, of class `cls` (`crate::world::may_return`):
    /// `False` for a class this knowledge does not have; a `ValueError` for a key the
    /// state does not hold.
    fn may_return(&self, state: &PyState, key: u64, cls: &str) -> PyResult<bool> {
        let Some(&class) = self.classes.get(cls) else {
            return Ok(false);
        };
        let entry = state.state.tracks.get(&key).ok_or_else(|| {
            PyValueError::new_err(format!("object version {key} is not in the state"))
        })?;
        Ok(crate::world::may_return(
            &entry.version,
            class,
            &self.filter.tables,
        ))
    }

    /// The world of `state` (a `CoreState`) predicted to `at` (`WorldModel.world`'s
    /// `_marginals` and, `mht`, `_same_objects`; `crate::world::at`), one row per
    /// physical object in the specification's order: `(lineage, existence, created,
    /// position, fields, confidence)`, `fields` the values of its `WorldObject`
    /// (`WorldModel._world_object`: its id, or `tentative_ids + 1 + lineage` for a
    /// lineage without one, the version's class, label and times, the prediction as
    /// tuples, mode probabilities by name for a filter of several modes, class
    /// probabilities of at least `class_floor` by name under `mht`) with `confidence`
    /// `None`, and `confidence` the lineage's value in `book` carried to `at`
    /// (`semwm.confidence.carried`; `None` without a book or under `paper`). `latest`
    /// is the model's latest state (a `CoreState`: its most probable hypothesis decides
    /// which lineages are distinct), `published` the objects shown now and `ids` their
    /// ids, as `Engine.current` takes them.
    #[allow(clippy::too_many_arguments)]
    fn world_at<'py>(
        &self,
        state: &Bound<'py, PyAny>,
        latest: &Bound<'py, PyAny>,
        at: f64,
        published: &Bound<'py, PyAny>,
        ids: &Bound<'py, PyDict>,
        book: Option<&PyBook>,
        tentative_ids: i64,
        class_floor: f64,
    ) -> PyResult<Vec<WorldRow<'py>>> {
        let py = state.py();
        let shown: KeySet<u64> = published_lineages(published)?.into_iter().collect();
        let ids = id_table(ids)?;
        let held = state
            .getattr("core")?
            .extract::<PyRef<'_, PyState>>()?
            .state
            .clone();
        let newest = latest
            .getattr("core")?
            .extract::<PyRef<'_, PyState>>()?
            .state
            .clone();
        let filter = self.filter.clone();
        let book = book
            .filter(|_| filter.tables.mht)
            .map(|book| book.book.clone());
        let d = filter.tables.dim;
        let values = run(py, "Engine.world_at", move || {
            let best = crate::world::best_keys(&newest);
            let (predicted, marginals) = crate::world::at(&filter, &held, at, &best, &shown, &ids)?;
            Ok(marginals
                .into_iter()
                .map(|(m, row)| -> WorldValues {
                    let version = held.tracks[&m.key].version.clone();
                    let predicted_row = &predicted.rows[row];
                    let mean = &predicted_row.mean;
                    let velocity =
                        (mean.len() > d).then(|| mean[d..(2 * d).min(mean.len())].to_vec());
                    // semwm.confidence.carried: 1 for a lineage the book does not hold
                    let decay = filter.tables.classes[version.cls].confidence_decay;
                    let confidence = book.as_ref().map(|book| match book.values.get(&m.lineage) {
                        None => 1.0,
                        Some(&(value, since)) => value * (-decay * (at - since).max(0.0)).exp(),
                    });
                    (
                        m.clone(),
                        ids.get(&m.lineage).copied(),
                        predicted.position(row).to_vec(),
                        predicted.covariance(row).to_vec(),
                        velocity,
                        predicted_row.mu().to_vec(),
                        version,
                        confidence,
                    )
                })
                .collect::<Vec<_>>())
        })?;
        let mht = self.filter.tables.mht;
        values
            .into_iter()
            .map(
                |(m, id, position, covariance, velocity, mu, version, confidence)| {
                    let position = PyTuple::new(py, position)?;
                    let covariance = PyTuple::new(
                        py,
                        covariance
                            .chunks_exact(d)
                            .map(|row| PyTuple::new(py, row))
                            .collect::<PyResult<Vec<_>>>()?,
                    )?;
                    let velocity = velocity.map(|v| PyTuple::new(py, v)).transpose()?;
                    let modes = match &self.mode_names[version.cls] {
                        None => None,
                        Some(names) if names.len() != mu.len() => {
                            return Err(PyValueError::new_err(format!(
                                "{} mode probabilities for {} modes",
                                mu.len(),
                                names.len()
                            )))
                        }
                        Some(names) => {
                            let modes = PyDict::new(py);
                            for (name, p) in names.iter().zip(&mu) {
                                modes.set_item(name.bind(py), p)?;
                            }
                            Some(modes)
                        }
                    };
                    let class_probabilities = if mht {
                        let probabilities = PyDict::new(py);
                        for (name, &p) in self.names.iter().zip(version.class_probs.iter()) {
                            if p >= class_floor {
                                probabilities.set_item(name.bind(py), p)?;
                            }
                        }
                        Some(probabilities)
                    } else {
                        None
                    };
                    let fields = PyDict::new(py);
                    let tentative = id.is_none();
                    let id = match id {
                        Some(id) => id,
                        None => i64::try_from(m.lineage)
                            .ok()
                            .and_then(|lineage| tentative_ids.checked_add(1)?.checked_add(lineage))
                            .ok_or_else(|| {
                                PyOverflowError::new_err(format!(
                                    "the tentative id of lineage {} is beyond 64 bits",
                                    m.lineage
                                ))
                            })?,
                    };
                    fields.set_item(intern!(py, "id"), id)?;
                    fields.set_item(intern!(py, "cls"), self.names[version.cls].bind(py))?;
                    fields.set_item(intern!(py, "label"), version.label.as_deref())?;
                    fields.set_item(intern!(py, "position"), &position)?;
                    fields.set_item(intern!(py, "velocity"), velocity)?;
                    fields.set_item(intern!(py, "covariance"), covariance)?;
                    fields.set_item(intern!(py, "existence"), m.existence.min(1.0))?;
                    fields.set_item(intern!(py, "last_seen"), version.last_seen)?;
                    fields.set_item(intern!(py, "created"), version.created)?;
                    fields.set_item(intern!(py, "mode_probabilities"), modes)?;
                    fields.set_item(intern!(py, "class_probabilities"), class_probabilities)?;
                    fields.set_item(intern!(py, "confidence"), py.None())?;
                    fields.set_item(intern!(py, "tentative"), tentative)?;
                    Ok((
                        m.lineage,
                        m.existence,
                        version.created,
                        position,
                        fields,
                        confidence,
                    ))
                },
            )
            .collect()
    }

    /// `WorldModel._publish` of `state` (a `CoreState`) with its common cases here:
    /// `(current, unchanged)`, one of them `None`. `unchanged` when no published object
    /// left the world (every lineage with an id and every published one is shown) and
    /// either no id waits for its object (`lost` false, `waiting` empty) or the ids
    /// that wait (`waiting`: their `(id, lineage)`, each already found able to return)
    /// keep waiting: no lineage is new, none of theirs is shown, no shown object holds
    /// one. Then `(ids, published, next_id)` as `WorldModel._publish_unchanged` makes
    /// them, new lineages taking the next ids in the published world's order (`ids`
    /// itself when there are none), `published` a `Published` table. Otherwise
    /// `current` as `Engine.current` gives it, for `WorldModel._publish_changed`
    /// (always when `lost`: waiting ids the core is not told of).
    #[pyo3(signature = (state, published, ids, lost, next_id, waiting=Vec::new()))]
    fn publish<'py>(
        slf: &Bound<'py, Self>,
        state: &Bound<'py, PyAny>,
        published: &Bound<'py, PyAny>,
        ids: &Bound<'py, PyDict>,
        lost: bool,
        next_id: i64,
        waiting: Vec<(i64, u64)>,
    ) -> PyResult<(Option<Bound<'py, PyDict>>, Option<Unchanged<'py>>)> {
        let engine = slf.get();
        let table = id_table(ids)?;
        let before: KeySet<u64> = published_lineages(published)?.into_iter().collect();
        let rows = engine.current_rows(state, before.clone(), &table)?;
        engine.published_after(state, &rows, table, &before, ids, lost, next_id, &waiting)
    }

    /// `process_and_advance` of `state` and `book` over `measurements`, then `publish`
    /// of the state after the scan, in one call (`WorldModel._ingest_scan`):
    /// `(after, book, current, unchanged)`, `after` the `CoreState` that `make_state`
    /// makes of the core's state after the scan. Under `paper` the book is not advanced
    /// (`WorldModel._step`): `book` is the one given.
    #[pyo3(signature = (state, book, measurements, published, ids, lost, next_id, waiting, make_state))]
    #[allow(clippy::too_many_arguments)]
    fn process_and_publish<'py>(
        slf: &Bound<'py, Self>,
        state: &PyState,
        book: &PyBook,
        measurements: &Bound<'py, PyAny>,
        published: &Bound<'py, PyAny>,
        ids: &Bound<'py, PyDict>,
        lost: bool,
        next_id: i64,
        waiting: Vec<(i64, u64)>,
        make_state: &Bound<'py, PyAny>,
    ) -> PyResult<ScanPublished<'py>> {
        let py = slf.py();
        let engine = slf.get();
        let scan = scan_rows(slf, measurements)?;
        let detectors: Vec<usize> = scan.iter().map(|m| m.detector).collect();
        let table = id_table(ids)?;
        let before: KeySet<u64> = published_lineages(published)?.into_iter().collect();
        let filter = engine.filter.clone();
        let summaries = engine.summaries.clone();
        let (held, held_book) = (state.state.clone(), book.book.clone());
        let (after, after_book, rows) = run(py, "Engine.process_and_publish", || {
            let after = filter.process_scan(&held, &scan, None)?;
            // paper 004's confidences are kept under `mht` only (`WorldModel._step`)
            let book = if filter.tables.mht {
                Arc::new(crate::confidence::advance(
                    &held_book,
                    &after,
                    &detectors,
                    None,
                    None,
                    &filter.tables,
                )?)
            } else {
                held_book
            };
            let rows = shown_rows(&after, &filter, &summaries, &before, &table);
            Ok((after, book, rows))
        })?;
        let after = Bound::new(
            py,
            PyState {
                state: Arc::new(after),
            },
        )?;
        let after = make_state.call1((after,))?;
        let (current, unchanged) =
            engine.published_after(&after, &rows, table, &before, ids, lost, next_id, &waiting)?;
        let book = PyBook { book: after_book };
        Ok((after, book, current, unchanged))
    }

    /// The confidence book after one scan (`semwm.confidence.advance`; `state` is the
    /// filter after it): `detectors` the scan's detections' detector indices, `view` its
    /// sensor view, `source` the view's source (`None` when it names none).
    #[pyo3(signature = (book, state, detectors, view=None, source=None))]
    fn advance(
        &self,
        py: Python<'_>,
        book: &PyBook,
        state: &PyState,
        detectors: Vec<usize>,
        view: Option<ViewRow>,
        source: Option<String>,
    ) -> PyResult<PyBook> {
        let filter = self.filter.clone();
        let (before, state) = (book.book.clone(), state.state.clone());
        if let Some(&bad) = detectors
            .iter()
            .find(|&&d| d >= filter.tables.detectors.len())
        {
            return Err(PyValueError::new_err(format!(
                "detectors: no detector {bad}"
            )));
        }
        let view = view.map(sensor_view);
        let source = source.map(Name::from);
        let after = run(py, "Engine.advance", move || {
            crate::confidence::advance(
                &before,
                &state,
                &detectors,
                view.as_ref(),
                source.as_ref(),
                &filter.tables,
            )
        })?;
        Ok(PyBook {
            book: Arc::new(after),
        })
    }

    /// The state after one scan (`MultipleHypothesisFilter.process_scan`): the Python
    /// engine's measurements as they are (`semwm.mhf.measurement.Measurement` named
    /// tuples: seq, time, class, z, R, detector, source, label, clutter rate, sensor,
    /// time std; detections sharing a source and a time), read here without a Python
    /// row per detection, and where the sensor looked (or `None`).
    /// `measurements` may also be a `Scan` the reader read for this engine.
    #[pyo3(signature = (state, measurements, view=None))]
    fn process_measurements(
        slf: &Bound<'_, Self>,
        py: Python<'_>,
        state: &PyState,
        measurements: &Bound<'_, PyAny>,
        view: Option<ViewRow>,
    ) -> PyResult<PyState> {
        let scan = scan_rows(slf, measurements)?;
        let filter = slf.get().filter.clone();
        let view = view.map(sensor_view);
        let before = state.state.clone();
        let after = run(py, "Engine.process_measurements", move || {
            filter.process_scan(&before, &scan, view.as_ref())
        })?;
        Ok(PyState {
            state: Arc::new(after),
        })
    }

    /// `process_measurements`, then `advance` of `book` over the state after the scan,
    /// in one call (`WorldModel._step`): `(state, book)`; `source` the view's source.
    #[pyo3(signature = (state, book, measurements, view=None, source=None))]
    fn process_and_advance(
        slf: &Bound<'_, Self>,
        py: Python<'_>,
        state: &PyState,
        book: &PyBook,
        measurements: &Bound<'_, PyAny>,
        view: Option<ViewRow>,
        source: Option<String>,
    ) -> PyResult<(PyState, PyBook)> {
        let scan = scan_rows(slf, measurements)?;
        let detectors: Vec<usize> = scan.iter().map(|m| m.detector).collect();
        let view = view.map(sensor_view);
        let source = source.map(Name::from);
        let filter = slf.get().filter.clone();
        let (before, before_book) = (state.state.clone(), book.book.clone());
        let (after, after_book) = run(py, "Engine.process_and_advance", move || {
            let after = filter.process_scan(&before, &scan, view.as_ref())?;
            let book = crate::confidence::advance(
                &before_book,
                &after,
                &detectors,
                view.as_ref(),
                source.as_ref(),
                &filter.tables,
            )?;
            Ok((after, book))
        })?;
        Ok((
            PyState {
                state: Arc::new(after),
            },
            PyBook {
                book: Arc::new(after_book),
            },
        ))
    }

    /// The class names, in the order of their indices.
    fn class_names(&self) -> Vec<String> {
        self.filter
            .tables
            .classes
            .iter()
            .map(|c| c.name.to_string())
            .collect()
    }
}

/// A state of the filter, kept in the core (`MHFState`).
#[pyclass(frozen, name = "State", module = "semwm._core")]
pub struct PyState {
    pub(crate) state: Arc<State>,
}

fn version_row<'py>(py: Python<'py>, entry: &Entry) -> PyResult<Bound<'py, pyo3::types::PyTuple>> {
    let v = &entry.version;
    let s = &v.state;
    let x = PyArray1::from_slice(py, &s.x).reshape([s.modes, s.size])?;
    let p = PyArray1::from_slice(py, &s.p).reshape([s.modes, s.size, s.size])?;
    let mu = s.mu.clone().into_pyarray(py);
    let probs = v.class_probs.to_vec().into_pyarray(py);
    let sources: Vec<String> = v.sources.iter().map(|n| n.to_string()).collect();
    (
        (
            v.key,
            v.lineage,
            v.cls,
            v.label.as_ref().map(|l| l.to_string()),
        ),
        (x, p, mu),
        (v.time, v.last_seen, v.created, v.rate),
        (probs, sources, entry.existence),
    )
        .into_pyobject(py)
}

#[pymethods]
impl PyState {
    /// The state before the first scan.
    #[staticmethod]
    fn empty() -> Self {
        PyState {
            state: Arc::new(State::empty()),
        }
    }

    /// A state from a Python `MHFState`'s parts (its clusters, versions, time, next key
    /// and observed rates); versions in any order, held once each.
    #[staticmethod]
    fn of(
        clusters: Vec<ClusterRow>,
        versions: Vec<VersionRow>,
        time: Option<f64>,
        next_key: u64,
        observed: &PyObservedRates,
    ) -> PyResult<Self> {
        let mut entries: Vec<(Key, Entry)> = Vec::with_capacity(versions.len());
        for row in versions {
            let ((key, lineage, cls, label), (modes, size, x, p, mu), times, rest) = row;
            let (time, last_seen, created, rate) = times;
            let (class_probs, sources, existence) = rest;
            if x.len() != modes * size || p.len() != modes * size * size || mu.len() != modes {
                return Err(PyValueError::new_err(format!(
                    "version {key}: x, P and mu do not fit {modes} modes of size {size}"
                )));
            }
            let mut sources: Vec<Name> = sources.into_iter().map(Name::from).collect();
            sources.sort();
            let version = Version {
                key,
                lineage,
                cls,
                label: label.map(Name::from),
                state: Arc::new(FilterState {
                    modes,
                    size,
                    x,
                    p,
                    mu,
                }),
                time,
                last_seen,
                created,
                rate,
                class_probs: class_probs.into(),
                sources: sources.into(),
            };
            entries.push((
                key,
                Entry {
                    version: Arc::new(version),
                    existence,
                    serial: next_serial(),
                },
            ));
        }
        // in key order, the last row of a key kept (as inserting each in turn would)
        let tracks: LiteMap<Key, Entry> = entries.into_iter().collect();
        let clusters = clusters
            .into_iter()
            .map(|hypotheses| {
                let hypotheses = hypotheses
                    .into_iter()
                    .map(|(log_weight, mut keys, rate)| {
                        keys.sort_unstable();
                        Hypothesis {
                            log_weight,
                            keys,
                            rate,
                        }
                    })
                    .collect();
                Arc::new(Cluster::of(hypotheses))
            })
            .collect();
        Ok(PyState {
            state: Arc::new(State {
                clusters,
                tracks,
                time,
                next_key,
                observed: observed.rates.clone(),
            }),
        })
    }

    #[getter]
    fn time(&self) -> Option<f64> {
        self.state.time
    }

    #[getter]
    fn next_key(&self) -> u64 {
        self.state.next_key
    }

    #[getter]
    fn hypothesis_count(&self) -> usize {
        self.state.hypothesis_count()
    }

    #[getter]
    fn cluster_count(&self) -> usize {
        self.state.clusters.len()
    }

    #[getter]
    fn track_count(&self) -> usize {
        self.state.tracks.len()
    }

    /// Each cluster's number of hypotheses.
    fn cluster_sizes(&self) -> Vec<usize> {
        self.state
            .clusters
            .iter()
            .map(|c| c.hypotheses.len())
            .collect()
    }

    /// Each cluster's identity (the address of its shared value: equal between two
    /// states while both are alive exactly when the cluster is the same one).
    fn cluster_ids(&self) -> Vec<usize> {
        self.state
            .clusters
            .iter()
            .map(|c| Arc::as_ptr(c) as usize)
            .collect()
    }

    /// The clusters at `indices` (all without): their hypotheses as (log weight, keys,
    /// rate).
    #[pyo3(signature = (indices=None))]
    fn clusters(&self, indices: Option<Vec<usize>>) -> PyResult<Vec<ClusterRow>> {
        let clusters = &self.state.clusters;
        let indices = indices.unwrap_or_else(|| (0..clusters.len()).collect());
        indices
            .into_iter()
            .map(|i| {
                let cluster = clusters.get(i).ok_or_else(|| {
                    PyValueError::new_err(format!("cluster {i}: only {} clusters", clusters.len()))
                })?;
                Ok(cluster
                    .hypotheses
                    .iter()
                    .map(|h| (h.log_weight, h.keys.clone(), h.rate))
                    .collect())
            })
            .collect()
    }

    /// Every version's key, serial number and existence, in key order.
    fn entries(&self) -> (Vec<u64>, Vec<u64>, Vec<f64>) {
        let tracks = &self.state.tracks;
        (
            tracks.keys().copied().collect(),
            tracks.values().map(|e| e.serial).collect(),
            tracks.values().map(|e| e.existence).collect(),
        )
    }

    /// The serial numbers of the versions of `keys`.
    fn serials(&self, keys: Vec<u64>) -> PyResult<Vec<u64>> {
        keys.iter()
            .map(|key| {
                self.state
                    .tracks
                    .get(key)
                    .map(|e| e.serial)
                    .ok_or_else(|| PyValueError::new_err(format!("no version {key} in this state")))
            })
            .collect()
    }

    /// The versions of `keys` as rows: (key, lineage, class index, label), (x `(M, n)`,
    /// P `(M, n, n)`, mu), (time, last seen, created, rate), (class probabilities,
    /// sources, existence).
    fn versions<'py>(
        &self,
        py: Python<'py>,
        keys: Vec<u64>,
    ) -> PyResult<Vec<Bound<'py, pyo3::types::PyTuple>>> {
        keys.iter()
            .map(|key| {
                let entry = self.state.tracks.get(key).ok_or_else(|| {
                    PyValueError::new_err(format!("no version {key} in this state"))
                })?;
                version_row(py, entry)
            })
            .collect()
    }

    /// Every lineage the state holds.
    fn lineages(&self) -> Vec<u64> {
        let mut lineages: Vec<u64> = self
            .state
            .tracks
            .values()
            .map(|e| e.version.lineage)
            .collect();
        lineages.sort_unstable();
        lineages.dedup();
        lineages
    }

    /// The keys of the most probable hypothesis (every cluster's first), sorted.
    fn best_keys(&self) -> Vec<u64> {
        let mut keys: Vec<u64> = self
            .state
            .clusters
            .iter()
            .flat_map(|c| c.hypotheses[0].keys.iter().copied())
            .collect();
        keys.sort_unstable();
        keys
    }

    /// The observed rates.
    fn observed(&self) -> PyObservedRates {
        PyObservedRates {
            rates: self.state.observed.clone(),
        }
    }
}
