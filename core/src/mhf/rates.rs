//! Detection rates observed on the sources' own streams (the `mht` model): the state
//! kept between scans by `semwm/mhf/rates.py`'s `ObservedRates`, which is its
//! specification (its module docstring states the model and its equations).
//!
//! Each detector of each source (a *stream*, `(source, detector)`) keeps the source's
//! mean interval between scans `Δ̄_s` and, per class `c`, discounted counts of the
//! chances it had to detect an object again and how many it took. Its per-scan
//! detection probability is the counts' posterior mean with the knowledge's prior,
//!
//! ```text
//! p̂_{s,d,c} = (hits + n₀ p₀) / (expected + n₀),   p₀ = min(1, f_c Δ̄_s),   n₀ = PRIOR_COUNTS
//! g_{s,d,c} = p̂_{s,d,c} / Δ̄_s                      (Hz)
//! f_{s,d}(o) = max(f_c, g_{s,d}) if (s, d) sees o, else f_c
//! f_s(o)     = max(f_c, max over the detectors d of s that detected o of g_{s,d})
//! ```
//!
//! and a scan's counts follow docs/knowledge.md's rules ("What semwm concludes from not
//! seeing something"): only the scan's own detectors count misses, an object counts from
//! its second detection, an object the scan's view did not hold is no chance, and the
//! counts are forgotten per chance (`DISCOUNT` each), not per scan.
//!
//! Every value is immutable: `after_scan` returns the rates after one scan, sharing
//! what did not change (names are `Arc<str>`, a lineage's streams an `Arc`).

use std::collections::{BTreeMap, BTreeSet};
use std::sync::{Arc, LazyLock};

use litemap::LiteMap;

use crate::mhf::hypotheses::{KeyMap, KeySet};

/// Strength (pseudo-counts) of the prior of a stream's per-scan detection probability.
pub const PRIOR_COUNTS: f64 = 10.0;
/// A stream sees an object for this many of its expected detection intervals after its
/// last detection of it.
pub const WINDOW_DETECTIONS: f64 = 3.0;
/// Weight of the newest interval in a source's mean interval between scans.
pub const INTERVAL_WEIGHT: f64 = 0.1;
/// Per chance to detect again, the weight kept by a stream's hit and miss counts.
pub const DISCOUNT: f64 = 0.99;
/// A scan counts as a miss for at most this many of its source's mean intervals.
pub const MAX_MISS_INTERVALS: f64 = 2.0;
/// A stream's detection rate of a class is judged after this many expected detections.
pub const MIN_EVIDENCE_SCANS: f64 = 20.0;

/// A source, detector or class name, shared between states.
pub type Name = Arc<str>;
/// `(source, detector)`; the source `""` for detections that name none.
pub type StreamKey = (Name, Name);
/// `(source, detector, class)`; the class `""` when the caller gave none.
pub type CountKey = (Name, Name, Name);

/// When a source last scanned, its mean interval between scans (s), where its sensor
/// was at that scan, and how fast the sensor moved between its last two scans (m/s).
#[derive(Debug, Clone, PartialEq)]
pub struct SourceClock {
    pub last_time: f64,
    pub interval: Option<f64>,
    pub position: Option<Vec<f64>>,
    pub speed: f64,
}

/// A stream's discounted counts and the lineages it detected in its detector's last
/// scan (`StreamCounts` in the specification).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StreamCounts {
    pub hits: f64,
    pub expected: f64,
    /// Shared between the rates of successive scans (a scan changes only its source's).
    pub detected: Arc<BTreeSet<u64>>,
}

impl StreamCounts {
    /// Posterior mean per-scan detection probability, prior mean `prior`.
    pub fn detection_probability(&self, prior: f64) -> f64 {
        (self.hits + PRIOR_COUNTS * prior) / (self.expected + PRIOR_COUNTS)
    }
}

/// A stream's false alarms: lineages it started that nothing confirmed yet, how many
/// of those died unconfirmed, and when it was first heard of (s).
#[derive(Debug, Clone, PartialEq)]
pub struct FalseAlarms {
    pub since: f64,
    pub pending: BTreeSet<u64>,
    pub count: u64,
}

impl FalseAlarms {
    /// After a scan: `started` lineages become pending, `confirmed` ones leave the
    /// pending set, and pending ones no longer `alive` count as false alarms.
    fn after(
        &self,
        started: impl IntoIterator<Item = u64>,
        confirmed: &KeySet<u64>,
        alive: &KeySet<u64>,
    ) -> FalseAlarms {
        let mut pending = BTreeSet::new();
        let mut dead = 0;
        for &lineage in &self.pending {
            if confirmed.contains(&lineage) {
                continue;
            }
            if alive.contains(&lineage) {
                pending.insert(lineage);
            } else {
                dead += 1;
            }
        }
        pending.extend(started);
        FalseAlarms {
            since: self.since,
            pending,
            count: self.count + dead,
        }
    }
}

/// Per stream that has detected a lineage, the time of its last detection of it.
pub type Seen = Vec<(StreamKey, f64)>;

/// What one scan tells the rates (the arguments of the specification's `after_scan`).
#[derive(Debug, Clone, Default)]
pub struct ScanReport {
    pub source: Name,
    pub time: f64,
    /// Per detector, the lineages that existed before the scan whose version in the most
    /// probable hypothesis took one of its detections.
    pub detected: LiteMap<Name, Vec<u64>>,
    /// Per detector, the new lineages it started in the most probable hypothesis.
    pub born: LiteMap<Name, Vec<u64>>,
    /// Every lineage the state holds after the scan.
    pub alive: KeySet<u64>,
    /// Where the source's sensor was.
    pub position: Option<Vec<f64>>,
    /// The class of each lineage detected or started (`None`: one count for all).
    pub classes: Option<KeyMap<u64, Name>>,
    /// Per detector, new lineages it started in other hypotheses only.
    pub born_elsewhere: LiteMap<Name, Vec<u64>>,
    /// The detectors that made the scan (`None`: every detector of the source).
    pub scanned: Option<BTreeSet<Name>>,
    /// Lineages the scan's sensor view did not hold.
    pub out_of_view: KeySet<u64>,
}

/// The observed rates of one state (`ObservedRates` in the specification).
#[derive(Debug, Clone, Default)]
pub struct ObservedRates {
    pub sources: LiteMap<Name, SourceClock>,
    pub streams: LiteMap<CountKey, StreamCounts>,
    pub seen: KeyMap<u64, Arc<Seen>>,
    pub false_alarms: LiteMap<StreamKey, FalseAlarms>,
}

fn name(text: &str) -> Name {
    Arc::from(text)
}

/// The class `""` (a caller that gives none), one for all: shared, not made per call.
fn no_class() -> Name {
    static NO_CLASS: LazyLock<Name> = LazyLock::new(|| name(""));
    NO_CLASS.clone()
}

/// The lineages a detector reported in a scan, asked for membership: by looking at each
/// when they are few (a scan's usual one or two), by a set when they are many.
struct Members<'a> {
    list: &'a [u64],
    set: Option<KeySet<u64>>,
}

impl<'a> Members<'a> {
    /// Above this many lineages a set answers.
    const LOOKED_AT: usize = 16;

    fn of(list: &'a [u64]) -> Members<'a> {
        let set = (list.len() > Self::LOOKED_AT).then(|| list.iter().copied().collect());
        Members { list, set }
    }

    fn contains(&self, lineage: &u64) -> bool {
        match &self.set {
            Some(set) => set.contains(lineage),
            None => self.list.contains(lineage),
        }
    }
}

impl ObservedRates {
    /// `g`: the stream's observed rate per object of class `cls` in view (Hz); 0 until
    /// its source has scanned twice. `class_rate`: the class's knowledge rate, the
    /// prior's mean (`min(1, f_c Δ̄_s)` per scan); else 1/2 per scan.
    pub fn rate(&self, source: &str, detector: &str, cls: &str, class_rate: Option<f64>) -> f64 {
        self.rate_of(&(name(source), name(detector), name(cls)), class_rate)
    }

    /// [`rate`](Self::rate) of the stream and class `key` names: the scan's callers hold
    /// the names, so that no name is made to look one up.
    fn rate_of(&self, key: &CountKey, class_rate: Option<f64>) -> f64 {
        let Some(clock) = self.sources.get(&key.0) else {
            return 0.0;
        };
        let Some(counts) = self.streams.get(key) else {
            return 0.0;
        };
        let interval = match clock.interval {
            Some(interval) if interval != 0.0 => interval,
            _ => return 0.0,
        };
        let prior = class_rate.map_or(0.5, |rate| (rate * interval).min(1.0));
        counts.detection_probability(prior) / interval
    }

    /// s: how long before `time` a scan of `source` says it kept looking: the time since
    /// its previous scan, at most `MAX_MISS_INTERVALS` of its mean interval; 0 for its
    /// first.
    pub fn miss_span(&self, source: &str, time: f64) -> f64 {
        let Some(clock) = self.sources.get(source) else {
            return 0.0;
        };
        if time <= clock.last_time {
            return 0.0;
        }
        let step = time - clock.last_time;
        match clock.interval {
            None => step,
            Some(interval) => step.min(MAX_MISS_INTERVALS * interval),
        }
    }

    /// `f_s(o)` of each object (Hz): the class's rate, raised to the observed rate of any
    /// of `source`'s detectors that has detected the object.
    pub fn source_rates(
        &self,
        source: &str,
        lineages: &[u64],
        class_rates: &[f64],
        classes: &[&Name],
    ) -> Vec<f64> {
        let mut result = class_rates.to_vec();
        if self.seen.is_empty() {
            return result;
        }
        // the first object of a (stream, class) sets its prior, as the specification's cache
        // (a few entries: a sorted vector, not a B-tree node of eleven)
        let mut rates: LiteMap<(&str, &str, &str), f64> = LiteMap::new();
        for (i, lineage) in lineages.iter().enumerate() {
            let Some(streams) = self.seen.get(lineage) else {
                continue;
            };
            for ((stream_source, detector), _) in streams.iter() {
                if &**stream_source != source {
                    continue;
                }
                let key = (&**stream_source, &**detector, &**classes[i]);
                let g = *rates.entry(key).or_insert_with(|| {
                    let stream = (stream_source.clone(), detector.clone(), classes[i].clone());
                    self.rate_of(&stream, Some(class_rates[i]))
                });
                if g > result[i] {
                    result[i] = g;
                }
            }
        }
        result
    }

    /// `f_{s,d}(o)` of each object (Hz) for a detection of `(source, detector)` at `time`
    /// (the specification's `from_stream`);
    /// `classes`: each object's class (else one count for all); `unconfirmed`: objects
    /// with no detection but the one that started them.
    pub fn stream_rates(
        &self,
        (source, detector): (&Name, &Name),
        lineages: &[u64],
        class_rates: &[f64],
        time: f64,
        classes: Option<&[&Name]>,
        unconfirmed: Option<&[bool]>,
    ) -> Vec<f64> {
        match self.sources.get(source) {
            Some(clock) if clock.interval.is_some_and(|interval| interval != 0.0) => {}
            _ => return class_rates.to_vec(), // every g is 0 until the source scanned twice
        }
        let mut by_class: LiteMap<&str, f64> = LiteMap::new();
        let g: Vec<f64> = (0..lineages.len())
            .map(|i| {
                let cls = classes.map_or("", |c| &**c[i]);
                *by_class.entry(cls).or_insert_with(|| {
                    let (cls, prior) = match classes {
                        Some(c) if !cls.is_empty() => (c[i].clone(), Some(class_rates[i])),
                        _ => (no_class(), None),
                    };
                    self.rate_of(&(source.clone(), detector.clone(), cls), prior)
                })
            })
            .collect();
        if !g.iter().any(|&value| value > 0.0) {
            return class_rates.to_vec();
        }
        lineages
            .iter()
            .enumerate()
            .map(|(i, lineage)| {
                let window = WINDOW_DETECTIONS / if g[i] > 0.0 { g[i] } else { 1.0 };
                let last = self
                    .seen
                    .get(lineage)
                    .and_then(|streams| {
                        streams
                            .iter()
                            .find(|((s, d), _)| s == source && d == detector)
                            .map(|(_, at)| *at)
                    })
                    .unwrap_or(f64::NEG_INFINITY);
                let mut recent = time - last <= window;
                if let Some(unconfirmed) = unconfirmed {
                    recent |= unconfirmed[i] && last > f64::NEG_INFINITY;
                }
                if g[i] > 0.0 && recent {
                    class_rates[i].max(g[i])
                } else {
                    class_rates[i]
                }
            })
            .collect()
    }

    /// Per class, the per-scan detection probability the stream `(source, detector)` is
    /// observed to have (prior: `priors`, each class's `detection_probability`), for the
    /// classes of `priors` it has expected `MIN_EVIDENCE_SCANS` detections of.
    pub fn detection_probabilities(
        &self,
        source: &str,
        detector: &str,
        priors: &BTreeMap<String, f64>,
    ) -> BTreeMap<String, f64> {
        let mut result = BTreeMap::new();
        for ((s, d, cls), counts) in &self.streams {
            if &**s != source || &**d != detector || counts.expected < MIN_EVIDENCE_SCANS {
                continue;
            }
            if let Some(&prior) = priors.get(&**cls) {
                result.insert(cls.to_string(), counts.detection_probability(prior));
            }
        }
        result
    }

    /// The rates after one scan (the specification's `after_scan`, whose docstring says
    /// what each argument means).
    pub fn after_scan(&self, scan: &ScanReport) -> ObservedRates {
        let source = &scan.source;
        let time = scan.time;
        let mut sources = self.sources.clone();
        let clock = match sources.get(source) {
            None => SourceClock {
                last_time: time,
                interval: None,
                position: scan.position.clone(),
                speed: 0.0,
            },
            Some(clock) if time > clock.last_time => {
                let step = time - clock.last_time;
                let interval = match clock.interval {
                    None => step,
                    Some(interval) => (1.0 - INTERVAL_WEIGHT) * interval + INTERVAL_WEIGHT * step,
                };
                let mut speed = clock.speed;
                if let (Some(now), Some(before)) = (&scan.position, &clock.position) {
                    let squared = now
                        .iter()
                        .zip(before)
                        .map(|(a, b)| (a - b) * (a - b))
                        .fold(0.0, |total, value| total + value);
                    speed = squared.sqrt() / step;
                }
                SourceClock {
                    last_time: time,
                    interval: Some(interval),
                    position: scan.position.clone(),
                    speed,
                }
            }
            Some(clock) => SourceClock {
                position: scan.position.clone(),
                ..clock.clone()
            },
        };
        sources.insert(source.clone(), clock);

        let class_of = |lineage: u64| -> Name {
            scan.classes
                .as_ref()
                .and_then(|classes| classes.get(&lineage).cloned())
                .unwrap_or_else(no_class)
        };
        let mut streams = self.streams.clone();
        // the streams the scan counts for, in key order, each once
        let mut keys: Vec<CountKey> = streams
            .keys()
            .filter(|(s, d, _)| {
                s == source && scan.scanned.as_ref().is_none_or(|used| used.contains(d))
            })
            .cloned()
            .collect();
        for (detector, lineages) in scan.detected.iter().chain(scan.born.iter()) {
            // a scan's detections mostly share their class: its key once, not per object
            let mut last: Option<Name> = None;
            for &lineage in lineages {
                let cls = class_of(lineage);
                if last.as_ref().is_some_and(|known| Arc::ptr_eq(known, &cls)) {
                    continue; // the same name: the key is in
                }
                keys.push((source.clone(), detector.clone(), cls.clone()));
                last = Some(cls);
            }
        }
        keys.sort_unstable();
        keys.dedup();
        let nothing = Vec::new();
        for key in keys {
            let (_, detector, cls) = &key;
            // a hit is any detection of the object by the stream, whatever class it now has
            let every = Members::of(scan.detected.get(detector).unwrap_or(&nothing));
            let now: BTreeSet<u64> = every
                .list
                .iter()
                .copied()
                .filter(|&lineage| class_of(lineage) == *cls)
                .collect();
            let old = streams.get(&key);
            if now.is_empty() && old.is_some_and(|old| old.detected.is_empty()) {
                // no lineage to expect, none detected: its counts stay as they are
                // (discounted by DISCOUNT^0 = 1, plus nothing)
                continue;
            }
            let (mut chances, mut hits) = (0usize, 0usize);
            for lineage in old.iter().flat_map(|old| old.detected.iter()) {
                if scan.alive.contains(lineage) && !scan.out_of_view.contains(lineage) {
                    chances += 1;
                    hits += usize::from(every.contains(lineage));
                }
            }
            let (old_hits, old_expected) = old.map_or((0.0, 0.0), |old| (old.hits, old.expected));
            let kept = DISCOUNT.powf(chances as f64); // forget by evidence, not by time
            streams.insert(
                key,
                StreamCounts {
                    hits: kept * old_hits + hits as f64,
                    expected: kept * old_expected + chances as f64,
                    detected: Arc::new(now), // a lineage counts once confirmed
                },
            );
        }

        // room for every lineage kept and every one the scan detected, without growing
        let reported = [&scan.detected, &scan.born, &scan.born_elsewhere]
            .into_iter()
            .flat_map(|by| by.values())
            .map(Vec::len)
            .sum::<usize>();
        let mut seen: KeyMap<u64, Arc<Seen>> =
            KeyMap::with_capacity_and_hasher(self.seen.len() + reported, Default::default());
        seen.extend(
            self.seen
                .iter()
                .filter(|(lineage, _)| scan.alive.contains(lineage))
                .map(|(lineage, streams)| (*lineage, streams.clone())),
        );
        let mut detectors: Vec<&Name> = scan
            .detected
            .keys()
            .chain(scan.born.keys())
            .chain(scan.born_elsewhere.keys())
            .collect();
        detectors.sort_unstable();
        detectors.dedup();
        for detector in &detectors {
            let stream: StreamKey = (source.clone(), (*detector).clone());
            let lineages = [&scan.detected, &scan.born, &scan.born_elsewhere]
                .into_iter()
                .flat_map(|by| by.get(*detector).unwrap_or(&nothing).iter().copied());
            for lineage in lineages {
                if !scan.alive.contains(&lineage) {
                    continue;
                }
                let entry = seen.entry(lineage).or_default();
                let streams = Arc::make_mut(entry);
                let same = |s: &StreamKey| {
                    (Arc::ptr_eq(&s.0, &stream.0) && Arc::ptr_eq(&s.1, &stream.1)) || *s == stream
                };
                match streams.iter_mut().find(|(s, _)| same(s)) {
                    Some((_, at)) => *at = time,
                    None => streams.push((stream.clone(), time)),
                }
            }
        }

        let mut alarms = self.false_alarms.clone();
        let mut confirmed: KeySet<u64> = KeySet::with_capacity_and_hasher(
            scan.detected.values().map(Vec::len).sum(),
            Default::default(),
        );
        confirmed.extend(scan.detected.values().flatten().copied());
        for detector in &detectors {
            alarms
                .entry((source.clone(), (*detector).clone()))
                .or_insert_with(|| FalseAlarms {
                    since: time,
                    pending: BTreeSet::new(),
                    count: 0,
                });
        }
        for ((stream_source, by), before) in alarms.iter_mut() {
            if stream_source != source {
                continue;
            }
            let started = [&scan.born, &scan.born_elsewhere]
                .into_iter()
                .flat_map(|from| from.get(by).unwrap_or(&nothing).iter().copied());
            *before = before.after(started, &confirmed, &scan.alive);
        }
        ObservedRates {
            sources,
            streams,
            seen,
            false_alarms: alarms,
        }
    }
}

/// What one scan without a sensor view tells about where its source looked
/// (`ScanCoverage`): its source, its detections' positions (`M x d`), where its sensor
/// was (the detections' `sensor_position`, or a static detector's position), the
/// largest range of its detectors when every one has one, and whether every detector of
/// it is static.
#[derive(Debug, Clone)]
pub struct ScanCoverage {
    pub source: Name,
    /// `M x dim`, row-major: one row per detection.
    pub positions: Vec<f64>,
    pub dim: usize,
    pub sensor: Option<Vec<f64>>,
    pub reach: Option<f64>,
    pub fixed: bool,
}

/// One object as `watched` reads it: the sources whose detections it took, its
/// estimate's position, its widest region margin, whether it is unconfirmed, and its
/// spread (m).
pub struct WatchedObject<'a> {
    pub sources: &'a [Name],
    pub position: &'a [f64],
    pub radius: f64,
    pub unconfirmed: bool,
    pub spread: f64,
}

/// The probability that the scan could have seen each object (`ObservedRates.watched`,
/// whose docstring states the three cases: the sensor's range, a static detector's
/// fixed coverage, and coverage learnt from what the source reports, within the convex
/// hull of its detections widened by the object's margin, or an unconfirmed object the
/// source started).
pub fn watched(scan: &ScanCoverage, objects: &[WatchedObject<'_>]) -> Vec<f64> {
    let count = objects.len();
    if count == 0 {
        return Vec::new();
    }
    if let (Some(sensor), Some(reach)) = (&scan.sensor, scan.reach) {
        let margins = objects.iter().any(|o| o.radius != 0.0);
        return objects
            .iter()
            .map(|o| {
                let reach = if margins {
                    (reach - o.radius).max(0.0)
                } else {
                    reach
                };
                crate::mhf::coverage::range_coverage(o.position, sensor, reach, Some(o.spread))
            })
            .collect();
    }
    if scan.fixed {
        return vec![1.0; count];
    }
    let by_source: Vec<bool> = objects
        .iter()
        .map(|o| o.sources.contains(&scan.source))
        .collect();
    if !by_source.iter().any(|&b| b) {
        return vec![0.0; count];
    }
    let mut near = vec![false; count];
    if !scan.positions.is_empty() && scan.dim > 0 {
        let rows: Vec<usize> = (0..count).filter(|&i| by_source[i]).collect();
        let d = objects[0].position.len().min(scan.dim);
        let points: Vec<f64> = rows
            .iter()
            .flat_map(|&i| objects[i].position[..d].iter().copied())
            .collect();
        let cut: Vec<f64>;
        let corners: &[f64] = if d == scan.dim {
            &scan.positions
        } else {
            cut = scan
                .positions
                .chunks(scan.dim)
                .flat_map(|p| p[..d].iter().copied())
                .collect();
            &cut
        };
        let distances = crate::mhf::coverage::hull_distance(&points, corners, d);
        for (&i, distance) in rows.iter().zip(distances) {
            near[i] = distance <= objects[i].radius;
        }
    }
    (0..count)
        .map(|i| {
            if by_source[i] && (near[i] || objects[i].unconfirmed) {
                1.0
            } else {
                0.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lineages(values: &[u64]) -> Vec<u64> {
        values.to_vec()
    }

    fn scan(time: f64, detected: &[u64], born: &[u64], alive: &[u64]) -> ScanReport {
        ScanReport {
            source: name("a"),
            time,
            detected: LiteMap::from_iter([(name("cam"), lineages(detected))]),
            born: LiteMap::from_iter([(name("cam"), lineages(born))]),
            alive: alive.iter().copied().collect(),
            ..ScanReport::default()
        }
    }

    #[test]
    fn a_streams_rate_is_its_scan_rate_times_its_detection_probability() {
        // scans every 0.1 s detecting the same object: hits = expected, p -> 1
        let mut rates = ObservedRates::default().after_scan(&scan(0.0, &[], &[7], &[7]));
        for k in 1..=30 {
            rates = rates.after_scan(&scan(f64::from(k) * 0.1, &[7], &[], &[7]));
        }
        let counts = &rates.streams[&(name("a"), name("cam"), name(""))];
        assert!(counts.expected > 25.0 && counts.hits == counts.expected);
        let g = rates.rate("a", "cam", "", None);
        let interval = rates.sources[&name("a")].interval.unwrap();
        assert!((interval - 0.1).abs() < 1e-9);
        let p = (counts.hits + PRIOR_COUNTS * 0.5) / (counts.expected + PRIOR_COUNTS);
        assert_eq!(g, p / interval);
    }

    #[test]
    fn a_miss_span_is_at_most_two_intervals_and_zero_for_the_first_scan() {
        let mut rates = ObservedRates::default();
        assert_eq!(rates.miss_span("a", 1.0), 0.0);
        rates = rates.after_scan(&scan(0.0, &[], &[], &[]));
        assert_eq!(rates.miss_span("a", 0.5), 0.5); // the second scan sets the interval
        rates = rates.after_scan(&scan(0.1, &[], &[], &[]));
        assert_eq!(rates.miss_span("a", 5.0), 0.2);
        assert_eq!(rates.miss_span("a", 0.05), 0.0);
    }

    #[test]
    fn lineages_that_are_gone_are_forgotten_and_count_as_false_alarms() {
        let rates = ObservedRates::default().after_scan(&scan(0.0, &[], &[3], &[3]));
        assert!(rates.seen.contains_key(&3));
        let alarms = &rates.false_alarms[&(name("a"), name("cam"))];
        assert_eq!(alarms.pending, BTreeSet::from([3]));
        let after = rates.after_scan(&scan(0.1, &[], &[], &[]));
        assert!(after.seen.is_empty());
        let alarms = &after.false_alarms[&(name("a"), name("cam"))];
        assert!(alarms.pending.is_empty());
        assert_eq!(alarms.count, 1);
    }

    #[test]
    fn a_lineage_out_of_view_is_no_chance_and_another_detectors_scan_no_miss() {
        let mut rates = ObservedRates::default().after_scan(&scan(0.0, &[], &[1], &[1]));
        rates = rates.after_scan(&scan(0.1, &[1], &[], &[1]));
        let key = (name("a"), name("cam"), name(""));
        let before = rates.streams[&key].expected;
        let mut away = scan(0.2, &[], &[], &[1]);
        away.out_of_view = [1].into_iter().collect();
        let turned = rates.after_scan(&away);
        assert_eq!(turned.streams[&key].expected, before);
        let mut other = scan(0.2, &[], &[], &[1]);
        other.detected = LiteMap::new();
        other.born = LiteMap::new();
        other.scanned = Some(BTreeSet::from([name("laser")]));
        assert_eq!(rates.after_scan(&other).streams[&key].expected, before);
    }

    #[test]
    fn stream_rates_raise_the_class_rate_only_while_the_stream_sees_the_object() {
        let mut rates = ObservedRates::default().after_scan(&scan(0.0, &[], &[1], &[1, 2]));
        for k in 1..=20 {
            rates = rates.after_scan(&scan(f64::from(k) * 0.1, &[1], &[], &[1, 2]));
        }
        let f = rates.stream_rates(
            (&name("a"), &name("cam")),
            &[1, 2],
            &[2.0, 2.0],
            2.1,
            None,
            None,
        );
        assert!(f[0] > 2.0, "{f:?}");
        assert_eq!(f[1], 2.0);
        let later = rates.stream_rates((&name("a"), &name("cam")), &[1], &[2.0], 60.0, None, None);
        assert_eq!(later, vec![2.0]);
    }
}
