//! `semwm._core.ObservedRates`: the observed rates (`crate::mhf::rates`) of a state kept
//! in the core, as plain rows: `state` and `of` convert to and from them, and
//! `semwm/mhf/core_engine.py` builds the specification's `ObservedRates` from them (a
//! Python state handed to the core, `GET /sources`' rate report).

use std::sync::Arc;

use pyo3::prelude::*;

use crate::mhf::rates::{FalseAlarms, Name, ObservedRates, SourceClock, StreamCounts};

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
                detected: Arc::new(detected.into_iter().collect()),
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
}
