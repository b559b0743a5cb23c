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
//!
//! Each scan it reads is a `Scan` (`scan.rs`): the core's rows for the engine the
//! reader was made for, its `Measurement` values made only if Python reads them.

use std::collections::HashMap;
use std::hash::BuildHasherDefault;
use std::sync::Arc;

use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyFloat, PyList, PyString, PyTuple, PyType};

use crate::mhf::hypotheses::KeyHasher;
use crate::mhf::measurement::{within_bounds, within_reach_or_margin, Measurement};
use crate::mhf::rates::Name;
use crate::python::scan::{Given, Makers, PyScan};

/// What a (class, detector) pair gives its detections (`semwm.validation._Resolved`),
/// with its detector's range and the region's bounds for the pair's noise.
struct Pair {
    /// The shared, read-only noise array, and its values (row-major).
    r: Py<PyAny>,
    r_values: Arc<[f64]>,
    trust_labels: bool,
    clutter_rate: Py<PyAny>,
    clutter_rate_value: f64,
    /// The class's and the detector's indices in the engine's tables.
    cls: usize,
    detector: usize,
    reach: Option<f64>,
    /// `out_of_range`'s one-dimensional gate quantile (`None`: no margin).
    gate: Option<f64>,
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
    let finite = |item: Bound<'_, PyAny>| bounded_float(&item, f64::MIN, f64::MAX);
    if let Ok(list) = value.cast_exact::<PyList>() {
        (list.len() == dim).then(|| list.iter().map(finite).collect())?
    } else {
        let tuple = value.cast_exact::<PyTuple>().ok()?;
        (tuple.len() == dim).then(|| tuple.iter().map(finite).collect())?
    }
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

/// A detection read: its core row, its Python values, and its scan's time as given.
struct Read<'py> {
    row: Measurement,
    given: Given,
    time: Bound<'py, PyAny>,
}

#[pyclass(name = "DetectionReader", module = "semwm._core", frozen)]
pub struct PyDetectionReader {
    makers: Arc<Makers>,
    detection: Py<PyType>,
    /// The engine whose tables the rows index (`semwm._core.Engine`).
    engine: Py<PyAny>,
    dim: usize,
    max_time: f64,
    max_time_std: f64,
    default_detector: Py<PyString>,
    /// class -> detector -> what the pair gives (KeyHasher: two lookups a detection).
    pairs: Pairs,
    zero: Py<PyAny>,
}

/// class -> detector -> [`Pair`].
type Pairs = HashMap<String, HashMap<String, Pair, KeyHashing>, KeyHashing>;
type KeyHashing = BuildHasherDefault<KeyHasher>;

impl PyDetectionReader {
    /// One detection read, or `None` when it is not plain. `last_source`: the previous
    /// detection's source name, shared when this one names the same.
    fn read_one<'py>(
        &self,
        py: Python<'py>,
        item: &Bound<'py, PyAny>,
        seq: u64,
        last_source: &mut Option<Name>,
    ) -> PyResult<Option<Reading<'py>>> {
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
        let (time_std, time_std_value) = match &fields.time_std {
            None => (self.zero.bind(py).clone(), 0.0),
            Some(value) => match bounded_float(value, 0.0, self.max_time_std) {
                None => return Ok(None),
                Some(0.0) => (self.zero.bind(py).clone(), 0.0), // `det.time_std or 0.0`
                Some(given) => (value.clone(), given),
            },
        };
        let sensor = match &fields.sensor {
            None => None,
            Some(value) => match finite_vector(value, self.dim) {
                Some(sensor) => Some(sensor),
                None => return Ok(None),
            },
        };
        let reached = sensor.as_ref().is_none_or(|sensor| {
            within_reach_or_margin(&z, sensor, pair.reach, &pair.r_values, pair.gate)
        });
        let inside = pair
            .bounds
            .as_ref()
            .is_none_or(|(low, high)| within_bounds(&z, low, high));
        if !(reached && inside) {
            return Ok(Some(Reading::Unplaced));
        }
        let label = match label {
            Some(label) if pair.trust_labels => Some(label),
            _ => None,
        };
        let source_text = match source {
            Some(source) => source.to_str()?,
            None => "",
        };
        let source_name = match last_source {
            Some(name) if &**name == source_text => name.clone(),
            _ => last_source.insert(Name::from(source_text)).clone(),
        };
        let row = Measurement {
            seq,
            time: time.cast_exact::<PyFloat>()?.value(),
            cls: pair.cls,
            z,
            r: pair.r_values.clone(),
            detector: pair.detector,
            source: source_name,
            label: match label {
                Some(label) => Some(Name::from(label.to_str()?)),
                None => None,
            },
            clutter_rate: pair.clutter_rate_value,
            sensor,
            time_std: time_std_value,
        };
        let given = Given {
            time: time.clone().unbind(),
            cls: cls.clone().into_any().unbind(),
            r: pair.r.clone_ref(py),
            detector: detector.clone().into_any().unbind(),
            source: source.map(|source| source.clone().into_any().unbind()),
            label: label.map(|label| label.clone().into_any().unbind()),
            clutter_rate: pair.clutter_rate.clone_ref(py),
            time_std: time_std.unbind(),
        };
        Ok(Some(Reading::Plain(Read {
            row,
            given,
            time: time.clone(),
        })))
    }
}

/// What the reader makes of a plain detection: its row, or that the specification
/// must place it (beyond its detector's reach of its sensor or outside the region's
/// bounds for its noise: `WorldModel._ignored` decides whether it is used).
#[allow(clippy::large_enum_variant)] // made and taken apart once per detection: no box
enum Reading<'py> {
    Plain(Read<'py>),
    Unplaced,
}

/// A scan being read: its key (as Python's and as the reader's), and its detections so
/// far.
struct Building<'py> {
    key: Bound<'py, PyTuple>,
    bits: u64,
    source: Name,
    rows: Vec<Measurement>,
    given: Vec<Given>,
}

/// A batch of up to this many scans finds a detection's scan by looking at each; one of
/// more, in a table (made when it gets there).
const SCANS_LOOKED_AT: usize = 8;

#[pymethods]
impl PyDetectionReader {
    /// `pairs`: `(class, detector) -> (R, trust_labels, clutter_rate, range, bounds,
    /// class index, detector index)`, with `bounds` the region's `(low, high)` for the
    /// pair's noise or `None`, and the indices those of `engine`'s tables.
    #[new]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        engine: Bound<'_, PyAny>,
        measurement: Bound<'_, PyType>,
        detection: Bound<'_, PyType>,
        dimension: usize,
        max_time: f64,
        max_time_std: f64,
        default_detector: Bound<'_, PyString>,
        pairs: Bound<'_, PyDict>,
    ) -> PyResult<Self> {
        type PairValues = (
            Py<PyAny>,
            bool,
            f64,
            Option<f64>,
            Option<(Vec<f64>, Vec<f64>)>,
            usize,
            usize,
            Option<f64>,
        );
        let mut table = Pairs::default();
        for (key, value) in pairs.iter() {
            let (cls, detector): (String, String) = key.extract()?;
            let (r, trust_labels, clutter_rate, reach, bounds, cls_index, detector_index, gate): PairValues =
                value.extract()?;
            let r_values: Vec<f64> = r
                .bind(py)
                .call_method0("ravel")?
                .call_method0("tolist")?
                .extract()?;
            let r_values: Arc<[f64]> = r_values.into();
            table.entry(cls).or_default().insert(
                detector,
                Pair {
                    r,
                    r_values,
                    trust_labels,
                    clutter_rate: PyFloat::new(py, clutter_rate).into_any().unbind(),
                    clutter_rate_value: clutter_rate,
                    cls: cls_index,
                    detector: detector_index,
                    reach,
                    gate,
                    bounds,
                },
            );
        }
        Ok(PyDetectionReader {
            makers: Arc::new(Makers {
                measurement: measurement.unbind(),
                tuple_new: py.get_type::<PyTuple>().getattr("__new__")?.unbind(),
            }),
            detection: detection.unbind(),
            engine: engine.unbind(),
            dim: dimension,
            max_time,
            max_time_std,
            default_detector: default_detector.unbind(),
            pairs: table,
            zero: PyFloat::new(py, 0.0).into_any().unbind(),
        })
    }

    /// How many detections of the batch it read (sequence numbers from `first_seq`),
    /// their scans as `semwm.world._grouped` groups them (key `(time, source or "")`,
    /// in order of first appearance), each a `Scan`, and the indices of the plain
    /// detections it left to the specification to place (`Reading::Unplaced`); or
    /// `None` when a detection is not plain: the specification reads that batch.
    #[allow(clippy::type_complexity)]
    fn read<'py>(
        &self,
        py: Python<'py>,
        batch: &Bound<'py, PyList>,
        first_seq: u64,
    ) -> PyResult<Option<(usize, Bound<'py, PyDict>, Vec<usize>)>> {
        let mut building: Vec<Building<'py>> = Vec::new();
        // scan keys (time with -0.0 as 0.0, as a dict's keys compare; source) -> index,
        // once the batch has more than SCANS_LOOKED_AT scans (KeyHasher: SipHash cost
        // about 200 instructions a detection)
        let mut index: HashMap<(u64, Name), usize, KeyHashing> = HashMap::default();
        // the scan of the previous detection: a batch's detections come in runs
        let mut current: Option<(f64, Name, usize)> = None;
        let mut last_source: Option<Name> = None;
        let mut unplaced: Vec<usize> = Vec::new();
        for (offset, item) in batch.iter().enumerate() {
            let seq = first_seq + offset as u64;
            let read = match self.read_one(py, &item, seq, &mut last_source)? {
                None => return Ok(None),
                Some(Reading::Unplaced) => {
                    unplaced.push(offset);
                    continue;
                }
                Some(Reading::Plain(read)) => read,
            };
            let (time, source) = (read.row.time, read.row.source.clone());
            let at = match &current {
                Some((last_time, last_source, at))
                    if *last_time == time && *last_source == source =>
                {
                    *at
                }
                _ => {
                    let bits = if time == 0.0 { 0.0f64 } else { time }.to_bits();
                    let found = if building.len() <= SCANS_LOOKED_AT {
                        building
                            .iter()
                            .position(|scan| scan.bits == bits && scan.source == source)
                    } else {
                        if index.is_empty() {
                            index.extend(
                                building
                                    .iter()
                                    .enumerate()
                                    .map(|(at, scan)| ((scan.bits, scan.source.clone()), at)),
                            );
                        }
                        index.get(&(bits, source.clone())).copied()
                    };
                    match found {
                        Some(at) => at,
                        None => {
                            // the key as `_grouped` makes it: `(m.time, m.source or "")`
                            let text = match &read.given.source {
                                Some(given) if !source.is_empty() => given.bind(py).clone(),
                                _ => intern!(py, "").clone().into_any(),
                            };
                            let key = PyTuple::new(py, [read.time.clone(), text])?;
                            building.push(Building {
                                key,
                                bits,
                                source: source.clone(),
                                // a batch of one detection (a robot's usual post)
                                // holds one row; else the vector's first growth
                                rows: Vec::with_capacity(batch.len().min(4)),
                                given: Vec::with_capacity(batch.len().min(4)),
                            });
                            if !index.is_empty() {
                                index.insert((bits, source.clone()), building.len() - 1);
                            }
                            building.len() - 1
                        }
                    }
                }
            };
            current = Some((time, source, at));
            let scan = &mut building[at];
            scan.rows.push(read.row);
            scan.given.push(read.given);
        }
        let scans = PyDict::new(py);
        for scan in building {
            let value = PyScan::new(
                scan.rows,
                scan.given,
                self.makers.clone(),
                self.engine.clone_ref(py),
            );
            scans.set_item(scan.key, Bound::new(py, value)?)?;
        }
        Ok(Some((batch.len() - unplaced.len(), scans, unplaced)))
    }
}
