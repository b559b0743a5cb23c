//! The Rust engine's reader of a batch's detections (`WorldModel._ingest`): a batch of
//! plain detections read straight into `Measurement`s, decided as the specification
//! decides it.
//!
//! The specification reads a batch in three passes: pydantic parses each dict into a
//! `Detection` (`semwm.validation.parse`), `check` resolves each against the knowledge
//! (`semwm.validation.check`), and `WorldModel._placed` keeps those within their
//! detector's reach and inside the region. When every detection of a batch is plain —
//! only known fields, values of their exact types within the `Detection` model's
//! bounds, a known class and detector, no covariance of its own, a position and sensor
//! position of the world's dimension, within its detector's reach and the region's
//! bounds — the reader makes the same measurements in one pass, and groups them by
//! scan as `semwm.world._grouped` does. For any other batch it
//! answers `None`, and the batch takes the specification's path, which reports every
//! problem and every detection it ignores. `tests/engines/test_reader.py` holds the two
//! paths equal.

use std::collections::HashMap;

use numpy::PyArray1;
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyFloat, PyList, PyString, PyTuple, PyType};

use crate::mhf::measurement::{within_bounds, within_reach};

/// What a (class, detector) pair gives its detections (`semwm.validation._Resolved`),
/// with its detector's range and the region's bounds for the pair's noise.
struct Pair {
    /// The shared, read-only noise array.
    r: Py<PyAny>,
    trust_labels: bool,
    clutter_rate: Py<PyAny>,
    reach: Option<f64>,
    /// `semwm.validation.region_bounds`: `None` without a region.
    bounds: Option<(Vec<f64>, Vec<f64>)>,
}

/// A detection's fields, as given (`None`: absent).
#[derive(Default)]
struct Fields<'py> {
    time: Option<Bound<'py, PyAny>>,
    cls: Option<Bound<'py, PyAny>>,
    position: Option<Bound<'py, PyAny>>,
    covariance: Option<Bound<'py, PyAny>>,
    source: Option<Bound<'py, PyAny>>,
    detector: Option<Bound<'py, PyAny>>,
    label: Option<Bound<'py, PyAny>>,
    sensor: Option<Bound<'py, PyAny>>,
    time_std: Option<Bound<'py, PyAny>>,
}

impl<'py> Fields<'py> {
    /// The fields of a dict whose class key is `class_key` (`"class"` for the wire's
    /// dicts, `"cls"` for a `Detection`'s attributes); `None` for a key it does not know.
    fn of(dict: &Bound<'py, PyDict>, class_key: &str) -> PyResult<Option<Self>> {
        let mut fields = Fields::default();
        for (key, value) in dict.iter() {
            let Ok(key) = key.cast_exact::<PyString>() else {
                return Ok(None);
            };
            let Ok(key) = key.to_str() else {
                return Ok(None); // not UTF-8 (a lone surrogate): no field of ours
            };
            let slot = match key {
                "time" => &mut fields.time,
                "position" => &mut fields.position,
                "covariance" => &mut fields.covariance,
                "source" => &mut fields.source,
                "detector" => &mut fields.detector,
                "label" => &mut fields.label,
                "sensor_position" => &mut fields.sensor,
                "time_std" => &mut fields.time_std,
                name if name == class_key => &mut fields.cls,
                _ => return Ok(None),
            };
            if !value.is_none() {
                *slot = Some(value);
            }
        }
        Ok(Some(fields))
    }
}

/// A float within `[low, high]` (no NaN), given as a Python float.
fn bounded_float(value: &Bound<'_, PyAny>, low: f64, high: f64) -> Option<f64> {
    let value = value.cast_exact::<PyFloat>().ok()?.value();
    (low <= value && value <= high).then_some(value)
}

/// A list or tuple of `dim` finite Python floats.
fn finite_vector(value: &Bound<'_, PyAny>, dim: usize) -> Option<Vec<f64>> {
    let items = if let Ok(list) = value.cast_exact::<PyList>() {
        list.iter().collect::<Vec<_>>()
    } else {
        value.cast_exact::<PyTuple>().ok()?.iter().collect()
    };
    if items.len() != dim {
        return None;
    }
    items
        .iter()
        .map(|item| bounded_float(item, f64::MIN, f64::MAX))
        .collect()
}

/// An exact Python string, or `None` when absent; `Err(())` for anything else.
fn name<'a, 'py>(
    value: &'a Option<Bound<'py, PyAny>>,
) -> Result<Option<&'a Bound<'py, PyString>>, ()> {
    match value {
        None => Ok(None),
        Some(value) => value.cast_exact::<PyString>().map(Some).map_err(|_| ()),
    }
}

/// A detection read: its `Measurement` and its scan's time and source.
struct Read<'py> {
    measurement: Bound<'py, PyAny>,
    time: Bound<'py, PyAny>,
    source: Option<Bound<'py, PyString>>,
}

impl Read<'_> {
    /// `m.source or ""`, the scan key's source.
    fn source_text(&self) -> PyResult<&str> {
        match &self.source {
            Some(source) => source.to_str(),
            None => Ok(""),
        }
    }
}

#[pyclass(name = "DetectionReader", module = "semwm._core", frozen)]
pub struct PyDetectionReader {
    measurement: Py<PyType>,
    detection: Py<PyType>,
    tuple_new: Py<PyAny>,
    dim: usize,
    max_time: f64,
    max_time_std: f64,
    default_detector: Py<PyString>,
    /// class -> detector -> what the pair gives.
    pairs: HashMap<String, HashMap<String, Pair>>,
    zero: Py<PyAny>,
}

impl PyDetectionReader {
    /// One plain detection as its `Measurement` with its scan's key (time, source), or
    /// `None`.
    fn read_one<'py>(
        &self,
        py: Python<'py>,
        item: &Bound<'py, PyAny>,
        seq: u64,
    ) -> PyResult<Option<Read<'py>>> {
        let fields = if let Ok(dict) = item.cast_exact::<PyDict>() {
            Fields::of(dict, "class")?
        } else if item.get_type().is(self.detection.bind(py)) {
            let attributes = item.getattr(intern!(py, "__dict__"))?;
            match attributes.cast_exact::<PyDict>() {
                Ok(dict) => Fields::of(dict, "cls")?,
                Err(_) => None,
            }
        } else {
            None
        };
        let Some(fields) = fields else {
            return Ok(None);
        };
        if fields.covariance.is_some() {
            return Ok(None); // its own noise: the specification checks and places it
        }
        let (Some(time), Some(cls), Some(position)) = (&fields.time, &fields.cls, &fields.position)
        else {
            return Ok(None);
        };
        if bounded_float(time, -self.max_time, self.max_time).is_none() {
            return Ok(None);
        }
        let Ok(cls) = cls.cast_exact::<PyString>() else {
            return Ok(None);
        };
        let (Ok(source), Ok(detector), Ok(label)) = (
            name(&fields.source),
            name(&fields.detector),
            name(&fields.label),
        ) else {
            return Ok(None);
        };
        let detector = detector.unwrap_or(self.default_detector.bind(py));
        let (Ok(cls_name), Ok(detector_name)) = (cls.to_str(), detector.to_str()) else {
            return Ok(None);
        };
        let Some(pair) = self
            .pairs
            .get(cls_name)
            .and_then(|detectors| detectors.get(detector_name))
        else {
            return Ok(None);
        };
        let Some(z) = finite_vector(position, self.dim) else {
            return Ok(None);
        };
        let time_std = match &fields.time_std {
            None => self.zero.bind(py).clone(),
            Some(value) => match bounded_float(value, 0.0, self.max_time_std) {
                None => return Ok(None),
                Some(0.0) => self.zero.bind(py).clone(), // `det.time_std or 0.0`
                Some(_) => value.clone(),
            },
        };
        let sensor = match &fields.sensor {
            None => py.None().into_bound(py),
            Some(value) => match finite_vector(value, self.dim) {
                Some(sensor) if within_reach(&z, &sensor, pair.reach) => {
                    PyArray1::from_slice(py, &sensor).into_any()
                }
                _ => return Ok(None),
            },
        };
        if let Some((low, high)) = &pair.bounds {
            if !within_bounds(&z, low, high) {
                return Ok(None);
            }
        }
        let none = || py.None().into_bound(py);
        let label = match label {
            Some(label) if pair.trust_labels => label.clone().into_any(),
            _ => none(),
        };
        let values: [Bound<'py, PyAny>; 11] = [
            seq.into_pyobject(py)?.into_any(),
            time.clone(),
            cls.clone().into_any(),
            PyArray1::from_slice(py, &z).into_any(),
            pair.r.bind(py).clone(),
            detector.clone().into_any(),
            source.map_or_else(none, |source| source.clone().into_any()),
            label,
            pair.clutter_rate.bind(py).clone(),
            sensor,
            time_std,
        ];
        let fields = PyTuple::new(py, values)?;
        let measurement = self
            .tuple_new
            .bind(py)
            .call1((self.measurement.bind(py), fields))?;
        Ok(Some(Read {
            measurement,
            time: time.clone(),
            source: source.cloned(),
        }))
    }
}

#[pymethods]
impl PyDetectionReader {
    /// `pairs`: `(class, detector) -> (R, trust_labels, clutter_rate, range, bounds)`,
    /// with `bounds` the region's `(low, high)` for the pair's noise or `None`.
    #[new]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        measurement: Bound<'_, PyType>,
        detection: Bound<'_, PyType>,
        dimension: usize,
        max_time: f64,
        max_time_std: f64,
        default_detector: Bound<'_, PyString>,
        pairs: Bound<'_, PyDict>,
    ) -> PyResult<Self> {
        type Given = (
            Py<PyAny>,
            bool,
            Py<PyAny>,
            Option<f64>,
            Option<(Vec<f64>, Vec<f64>)>,
        );
        let mut table: HashMap<String, HashMap<String, Pair>> = HashMap::new();
        for (key, value) in pairs.iter() {
            let (cls, detector): (String, String) = key.extract()?;
            let (r, trust_labels, clutter_rate, reach, bounds): Given = value.extract()?;
            table.entry(cls).or_default().insert(
                detector,
                Pair {
                    r,
                    trust_labels,
                    clutter_rate,
                    reach,
                    bounds,
                },
            );
        }
        Ok(PyDetectionReader {
            measurement: measurement.unbind(),
            detection: detection.unbind(),
            tuple_new: py.get_type::<PyTuple>().getattr("__new__")?.unbind(),
            dim: dimension,
            max_time,
            max_time_std,
            default_detector: default_detector.unbind(),
            pairs: table,
            zero: PyFloat::new(py, 0.0).into_any().unbind(),
        })
    }

    /// The batch's measurements (sequence numbers from `first_seq`) and the same
    /// grouped by scan as `semwm.world._grouped` groups them (key `(time, source or
    /// "")`, in order of first appearance), or `None` when a detection is not plain:
    /// the specification reads that batch.
    #[allow(clippy::type_complexity)]
    fn read<'py>(
        &self,
        py: Python<'py>,
        batch: &Bound<'py, PyList>,
        first_seq: u64,
    ) -> PyResult<Option<(Bound<'py, PyList>, Bound<'py, PyDict>)>> {
        let measurements = PyList::empty(py);
        let scans = PyDict::new(py);
        // the scan of the previous detection: a batch's detections come in runs
        let mut current: Option<(Read<'py>, Bound<'py, PyList>)> = None;
        for (index, item) in batch.iter().enumerate() {
            let Some(read) = self.read_one(py, &item, first_seq + index as u64)? else {
                return Ok(None);
            };
            measurements.append(&read.measurement)?;
            if let Some((last, scan)) = &current {
                let same_time = last.time.cast_exact::<PyFloat>()?.value()
                    == read.time.cast_exact::<PyFloat>()?.value();
                if same_time && last.source_text()? == read.source_text()? {
                    scan.append(&read.measurement)?;
                    continue;
                }
            }
            let source = match &read.source {
                Some(source) if !source.to_str()?.is_empty() => source.clone(),
                _ => intern!(py, "").clone(),
            };
            let key = PyTuple::new(py, [read.time.clone(), source.into_any()])?;
            let scan = match scans.get_item(&key)? {
                Some(scan) => scan.cast_into::<PyList>()?,
                None => {
                    let scan = PyList::empty(py);
                    scans.set_item(&key, &scan)?;
                    scan
                }
            };
            scan.append(&read.measurement)?;
            current = Some((read, scan));
        }
        Ok(Some((measurements, scans)))
    }
}
