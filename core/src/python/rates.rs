//! `semwm._core.ObservedRates`: the observed rates (`crate::mhf::rates`) kept in the core
//! between scans, with the methods of the specification's `ObservedRates`
//! (`semwm/mhf/rates.py`) that the scan calls; `semwm/mhf/rust_rates.py` wraps it.
//!
//! Immutable, as the specification's: `after_scan` returns new rates, sharing the old
//! ones' unchanged parts. `state` and `of` convert to and from plain tuples (the
//! specification's dataclasses are built from them in Python).

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::sync::Arc;

use numpy::{IntoPyArray, PyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::error::{KernelError, KernelResult};
use crate::mhf::hypotheses::{KeyMap, KeySet};
use crate::mhf::rates::{FalseAlarms, Name, ObservedRates, ScanReport, SourceClock, StreamCounts};
use crate::python::run;

/// A source's clock: name, last scan time, mean interval, sensor position, speed.
type ClockRow = (String, f64, Option<f64>, Option<Vec<f64>>, f64);
/// A stream's counts: source, detector, class, hits, expected, lineages detected.
type CountRow = (String, String, String, f64, f64, Vec<u64>);
/// A lineage and its streams' last detections: (source, detector, time).
type SeenRow = (u64, Vec<(String, String, f64)>);
/// A stream's false alarms: source, detector, since, pending lineages, count.
type AlarmRow = (String, String, f64, Vec<u64>, u64);

fn named(text: String) -> Name {
    Arc::from(text)
}

fn by_detector(entries: BTreeMap<String, Vec<u64>>) -> BTreeMap<Name, Vec<u64>> {
    entries.into_iter().map(|(k, v)| (named(k), v)).collect()
}

/// Per object, the same length as `lineages`.
fn expect_rows(name: &str, got: usize, count: usize) -> KernelResult<()> {
    if got == count {
        Ok(())
    } else {
        Err(KernelError::Shape(format!(
            "{name}: expected {count} values (one per lineage), got {got}"
        )))
    }
}

/// The observed rates of one state (`semwm.mhf.rates.ObservedRates` in the core).
#[pyclass(name = "ObservedRates", module = "semwm._core", frozen)]
pub struct PyObservedRates {
    pub(crate) rates: Arc<ObservedRates>,
}

#[pymethods]
impl PyObservedRates {
    #[new]
    fn new() -> Self {
        PyObservedRates {
            rates: Arc::new(ObservedRates::default()),
        }
    }

    /// The rates from plain rows (`state`'s layout).
    #[staticmethod]
    fn of(
        sources: Vec<ClockRow>,
        streams: Vec<CountRow>,
        seen: Vec<SeenRow>,
        false_alarms: Vec<AlarmRow>,
    ) -> Self {
        let mut rates = ObservedRates::default();
        for (source, last_time, interval, position, speed) in sources {
            let clock = SourceClock {
                last_time,
                interval,
                position,
                speed,
            };
            rates.sources.insert(named(source), clock);
        }
        for (source, detector, cls, hits, expected, detected) in streams {
            let counts = StreamCounts {
                hits,
                expected,
                detected: detected.into_iter().collect(),
            };
            let key = (named(source), named(detector), named(cls));
            rates.streams.insert(key, counts);
        }
        for (lineage, streams) in seen {
            let streams = streams
                .into_iter()
                .map(|(s, d, at)| ((named(s), named(d)), at))
                .collect();
            rates.seen.insert(lineage, Arc::new(streams));
        }
        for (source, detector, since, pending, count) in false_alarms {
            let alarms = FalseAlarms {
                since,
                pending: pending.into_iter().collect(),
                count,
            };
            rates
                .false_alarms
                .insert((named(source), named(detector)), alarms);
        }
        PyObservedRates {
            rates: Arc::new(rates),
        }
    }

    /// The rates as plain rows: sources, streams, seen (lineages in increasing order),
    /// false alarms.
    fn state(&self) -> (Vec<ClockRow>, Vec<CountRow>, Vec<SeenRow>, Vec<AlarmRow>) {
        let rates = &self.rates;
        let sources = rates
            .sources
            .iter()
            .map(|(s, c)| {
                let position = c.position.clone();
                (s.to_string(), c.last_time, c.interval, position, c.speed)
            })
            .collect();
        let streams = rates
            .streams
            .iter()
            .map(|((s, d, c), counts)| {
                let detected = counts.detected.iter().copied().collect();
                let (hits, expected) = (counts.hits, counts.expected);
                (
                    s.to_string(),
                    d.to_string(),
                    c.to_string(),
                    hits,
                    expected,
                    detected,
                )
            })
            .collect();
        let mut seen: Vec<SeenRow> = rates
            .seen
            .iter()
            .map(|(lineage, streams)| {
                let rows = streams
                    .iter()
                    .map(|((s, d), at)| (s.to_string(), d.to_string(), *at))
                    .collect();
                (*lineage, rows)
            })
            .collect();
        seen.sort_by_key(|row| row.0);
        let alarms = rates
            .false_alarms
            .iter()
            .map(|((s, d), a)| {
                let pending = a.pending.iter().copied().collect();
                (s.to_string(), d.to_string(), a.since, pending, a.count)
            })
            .collect();
        (sources, streams, seen, alarms)
    }

    fn miss_span(&self, source: &str, time: f64) -> f64 {
        self.rates.miss_span(source, time)
    }

    fn source_rates<'py>(
        &self,
        py: Python<'py>,
        source: String,
        lineages: Vec<u64>,
        class_rates: Vec<f64>,
        classes: Vec<String>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let rates = self.rates.clone();
        let result = run(py, "ObservedRates.source_rates", move || {
            expect_rows("class_rates", class_rates.len(), lineages.len())?;
            expect_rows("classes", classes.len(), lineages.len())?;
            let classes: Vec<&str> = classes.iter().map(String::as_str).collect();
            Ok(rates.source_rates(&source, &lineages, &class_rates, &classes))
        })?;
        Ok(result.into_pyarray(py))
    }

    /// `ObservedRates.from_stream`.
    #[pyo3(name = "from_stream", signature = (source, detector, lineages, class_rates, time, classes=None, unconfirmed=None))]
    #[allow(clippy::too_many_arguments)]
    fn stream_rates<'py>(
        &self,
        py: Python<'py>,
        source: String,
        detector: String,
        lineages: Vec<u64>,
        class_rates: Vec<f64>,
        time: f64,
        classes: Option<Vec<String>>,
        unconfirmed: Option<Vec<bool>>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let rates = self.rates.clone();
        let result = run(py, "ObservedRates.from_stream", move || {
            let count = lineages.len();
            expect_rows("class_rates", class_rates.len(), count)?;
            if let Some(classes) = &classes {
                expect_rows("classes", classes.len(), count)?;
            }
            if let Some(unconfirmed) = &unconfirmed {
                expect_rows("unconfirmed", unconfirmed.len(), count)?;
            }
            let names: Option<Vec<&str>> = classes
                .as_ref()
                .map(|c| c.iter().map(String::as_str).collect());
            Ok(rates.stream_rates(
                (&source, &detector),
                &lineages,
                &class_rates,
                time,
                names.as_deref(),
                unconfirmed.as_deref(),
            ))
        })?;
        Ok(result.into_pyarray(py))
    }

    fn detection_probabilities(
        &self,
        source: &str,
        detector: &str,
        priors: BTreeMap<String, f64>,
    ) -> BTreeMap<String, f64> {
        self.rates
            .detection_probabilities(source, detector, &priors)
    }

    /// The rates after one scan (`ObservedRates.after_scan`'s arguments).
    #[pyo3(signature = (
        source, time, detected, born, alive, position=None, classes=None,
        born_elsewhere=None, scanned=None, out_of_view=HashSet::new()
    ))]
    #[allow(clippy::too_many_arguments)]
    fn after_scan(
        &self,
        py: Python<'_>,
        source: String,
        time: f64,
        detected: BTreeMap<String, Vec<u64>>,
        born: BTreeMap<String, Vec<u64>>,
        alive: KeySet<u64>,
        position: Option<Vec<f64>>,
        classes: Option<HashMap<u64, String>>,
        born_elsewhere: Option<BTreeMap<String, Vec<u64>>>,
        scanned: Option<BTreeSet<String>>,
        out_of_view: HashSet<u64>,
    ) -> PyResult<Self> {
        if !time.is_finite() {
            return Err(PyValueError::new_err(format!(
                "time: expected a finite time, got {time}"
            )));
        }
        let report = ScanReport {
            source: named(source),
            time,
            detected: by_detector(detected),
            born: by_detector(born),
            alive,
            position,
            classes: classes.map(|c| {
                c.into_iter()
                    .map(|(l, n)| (l, named(n)))
                    .collect::<KeyMap<u64, Name>>()
            }),
            born_elsewhere: born_elsewhere.map(by_detector).unwrap_or_default(),
            scanned: scanned.map(|s| s.into_iter().map(named).collect()),
            out_of_view: out_of_view.into_iter().collect(),
        };
        let rates = self.rates.clone();
        let after = run(py, "ObservedRates.after_scan", move || {
            Ok(rates.after_scan(&report))
        })?;
        Ok(PyObservedRates {
            rates: Arc::new(after),
        })
    }
}
