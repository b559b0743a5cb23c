//! The knowledge-driven Multiple Hypothesis Filter: one scan, from a state to the next
//! (`MultipleHypothesisFilter.process_scan`, `semwm/mhf/filter.py`, whose module
//! docstring gives the steps; paper 002 Section III, paper 000 III):
//!
//! 1. every stored version is predicted to the scan time (`crate::mhf::predict`);
//! 2. `mht`: every version's existence is carried to the scan time and every hypothesis
//!    weighted by its objects' missed-detection likelihoods (`existence_at`,
//!    `undetected`; docs/knowledge.md, "What semwm concludes from not seeing something");
//! 3. objects that became too uncertain (P_max, paper 002 III-E), went unseen too long
//!    (paper 000 C3), or whose existence inside the region fell below
//!    `removal_existence` are removed from every hypothesis (`leaving`, `without`);
//! 4. the scan's options are computed once (`crate::mhf::association`); with a sensor
//!    view, objects in view that the scan did not report lose existence (`looked_at`);
//! 5. detection by detection, the hypotheses are expanded (`crate::mhf::expansion`) and
//!    near-identical twins merged (`crate::mhf::similar`);
//! 6. versions no hypothesis holds are dropped, and the observed rates learn from the
//!    scan (`observe`).
//!
//! Each function is named after the method it mirrors; the Python engine is the
//! specification, and where it iterates a set this code iterates in key order, as the
//! specification does.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use litemap::LiteMap;

use crate::error::{KernelError, KernelResult};
use crate::mhf::association::{self, Inputs, ScanOption};
use crate::mhf::coverage::symmetric_eigen;
use crate::mhf::existence::{inside_probability, missed, survive};
use crate::mhf::expansion::{self, split_with, Op};
use crate::mhf::hypotheses::{fsum, key_union, prune, Cluster, Hypothesis, KeyMap, KeySet, Merged};
use crate::mhf::measurement::{Measurement, SensorView};
use crate::mhf::predict::{predict, Predicted};
use crate::mhf::rates::{watched, Name, ObservedRates, ScanCoverage, ScanReport, WatchedObject};
use crate::mhf::similar::merge_similar_in;
use crate::mhf::state::{next_serial, Entry, Key, State, Version};
use crate::mhf::tables::Tables;

/// The largest eigenvalue of a symmetric `d x d` matrix (`largest_eigenvalue`: closed
/// forms for `d <= 2`).
pub fn largest_eigenvalue(c: &[f64], d: usize) -> f64 {
    match d {
        1 => c[0],
        2 => {
            let (a, b, cc) = (c[0], c[1], c[3]);
            let half = 0.5 * (a - cc);
            0.5 * (a + cc) + (half * half + b * b).sqrt()
        }
        _ => symmetric_eigen(c, d).0[0],
    }
}

/// `numpy.minimum` of two floats: NaN if either is.
fn np_minimum(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.min(b)
    }
}

/// The scan's working track table (`_TrackTable`): every version the scan can name
/// (the state's and the new ones) and each version's existence.
struct Table {
    versions: KeyMap<Key, Arc<Version>>,
    existence: KeyMap<Key, f64>,
}

impl Table {
    fn version(&self, key: Key) -> KernelResult<&Arc<Version>> {
        self.versions.get(&key).ok_or_else(|| {
            KernelError::Value(format!("object version {key} is held but not stored"))
        })
    }

    fn rate(&self, key: Key) -> KernelResult<f64> {
        Ok(self.version(key)?.rate)
    }

    fn add(&mut self, version: Arc<Version>, existence: f64) {
        self.existence.insert(version.key, existence);
        self.versions.insert(version.key, version);
    }
}

/// The filter for one knowledge base.
#[derive(Debug, Clone)]
pub struct Filter {
    pub tables: Tables,
}

impl Filter {
    pub fn new(tables: Tables) -> KernelResult<Filter> {
        tables.validate()?;
        Ok(Filter { tables })
    }

    /// Leave rates mu (Hz) of predicted objects (`leave_rates`): the class's
    /// `leave_frequency`, or a disappearance relation's rate near its target.
    pub fn leave_rates(&self, predicted: &Predicted) -> Vec<f64> {
        predicted
            .rows
            .iter()
            .enumerate()
            .map(|(i, row)| {
                let spec = &self.tables.classes[row.version.cls];
                let mut rate = spec.leave_frequency;
                let position = predicted.position(i);
                for relation in &spec.leave_relations {
                    if relation.frequency > rate {
                        let mut squared = 0.0;
                        for (a, b) in position.iter().zip(&relation.target) {
                            squared += (a - b) * (a - b);
                        }
                        if squared.sqrt() <= relation.max_distance {
                            rate = relation.frequency;
                        }
                    }
                }
                rate
            })
            .collect()
    }

    /// Each predicted object's probability of being inside the region, its position
    /// variances capped at its class's measurement noise where the class has no P_max
    /// (`inside`).
    pub fn inside(&self, predicted: &Predicted) -> Vec<f64> {
        let d = self.tables.dim;
        let Some(region) = &self.tables.region else {
            return vec![1.0; predicted.len()];
        };
        let low: Vec<f64> = region.iter().map(|(a, _)| *a).collect();
        let high: Vec<f64> = region.iter().map(|(_, b)| *b).collect();
        // the capped covariance (diagonal), one buffer for all objects: on the stack for
        // a world of up to 4 dimensions
        let mut on_stack = [0.0; 16];
        let mut on_heap = Vec::new();
        let capped: &mut [f64] = if d * d <= on_stack.len() {
            &mut on_stack[..d * d]
        } else {
            on_heap.resize(d * d, 0.0);
            &mut on_heap
        };
        (0..predicted.len())
            .map(|i| {
                let spec = &self.tables.classes[predicted.rows[i].version.cls];
                let full = predicted.covariance(i);
                for a in 0..d {
                    capped[a * d + a] = np_minimum(full[a * d + a], spec.region_cap[a]);
                }
                inside_probability(
                    predicted.position(i),
                    capped,
                    &low,
                    &high,
                    Some(&spec.region_margin),
                )
            })
            .collect()
    }

    /// Each object's widest region margin (`region_margins(...).max(axis=1)`).
    fn radius(&self, predicted: &Predicted) -> Vec<f64> {
        predicted
            .rows
            .iter()
            .map(|row| {
                self.tables.classes[row.version.cls]
                    .region_margin
                    .iter()
                    .copied()
                    .fold(f64::NEG_INFINITY, f64::max)
            })
            .collect()
    }

    /// Detection rates f (Hz) with which the scan misses each predicted object
    /// (`miss_rates`): its source's rate for the objects it could have seen, times the
    /// probability that the object is inside the region; 0 for every other object.
    fn miss_rates(
        &self,
        observed: &ObservedRates,
        predicted: &Predicted,
        scan: &ScanCoverage,
        inside: &[f64],
    ) -> Vec<f64> {
        let radius = self.radius(predicted);
        let spread = predicted.spread();
        let objects: Vec<WatchedObject<'_>> = predicted
            .rows
            .iter()
            .enumerate()
            .map(|(i, row)| WatchedObject {
                sources: &row.version.sources,
                position: predicted.position(i),
                radius: radius[i],
                unconfirmed: row.version.unconfirmed(),
                spread: spread[i],
            })
            .collect();
        let seen = watched(scan, &objects);
        if !seen.iter().any(|&w| w != 0.0) {
            return vec![0.0; predicted.len()];
        }
        let mut f: Vec<f64> = predicted
            .rows
            .iter()
            .map(|row| self.tables.classes[row.version.cls].detection_frequency)
            .collect();
        if self.tables.observed_rates {
            let lineages: Vec<u64> = predicted.rows.iter().map(|r| r.version.lineage).collect();
            let classes: Vec<&Name> = predicted
                .rows
                .iter()
                .map(|r| &self.tables.classes[r.version.cls].name)
                .collect();
            f = observed.source_rates(&scan.source, &lineages, &f, &classes);
        }
        (0..predicted.len())
            .map(|i| f[i] * seen[i] * inside[i])
            .collect()
    }

    /// Existence of every predicted version at `time` (>= the state's time) and, for a
    /// scan without a sensor view (`scan`), the log missed-detection likelihood of each
    /// (`existence_at`): objects leave at their leave rate; a scan that could have seen
    /// an object misses it at its source's rate over the time since the source's
    /// previous scan; silence and time alone are never a miss.
    pub(crate) fn existence_at(
        &self,
        state: &State,
        predicted: &Predicted,
        time: f64,
        scan: Option<&ScanCoverage>,
        inside: &[f64],
    ) -> (Vec<f64>, Option<Vec<f64>>) {
        let mut r: Vec<f64> = predicted
            .rows
            .iter()
            .map(|row| state.existence(row.version.key))
            .collect();
        let Some(before) = state.time else {
            return (r, None);
        };
        if !self.tables.mht || predicted.is_empty() {
            return (r, None);
        }
        if time > before {
            let mu = self.leave_rates(predicted);
            if mu.iter().any(|&m| m != 0.0) {
                for (value, &m) in r.iter_mut().zip(&mu) {
                    *value = survive(*value, m, 0.0, time - before).0;
                }
            }
        }
        let mut log_q = None;
        if let (Some(scan), true) = (scan, self.tables.missed_detections) {
            let span = state.observed.miss_span(&scan.source, time);
            if span > 0.0 {
                let f = self.miss_rates(&state.observed, predicted, scan, inside);
                if f.iter().any(|&value| value != 0.0) {
                    let mut q = Vec::with_capacity(r.len());
                    for (value, &rate) in r.iter_mut().zip(&f) {
                        let (r_new, log) = survive(*value, 0.0, rate, span);
                        *value = r_new;
                        q.push(log);
                    }
                    log_q = Some(q);
                }
            }
        }
        (r, log_q)
    }

    /// Rows of objects to remove at `time` (`leaving`): position covariance above the
    /// class's P_max (paper 002 III-E), unseen longer than its maximum (C3), not finite,
    /// and (`mht`) existence inside the region below `removal_existence`.
    pub(crate) fn leaving(
        &self,
        predicted: &Predicted,
        time: f64,
        existence: &[f64],
        inside: &[f64],
    ) -> Vec<bool> {
        let d = self.tables.dim;
        (0..predicted.len())
            .map(|i| {
                let version = &predicted.rows[i].version;
                let spec = &self.tables.classes[version.cls];
                let mut drop = false;
                if self.tables.mht {
                    drop |= existence[i] * inside[i] < self.tables.removal_existence;
                }
                let covariance = predicted.covariance(i);
                let finite = covariance.iter().all(|v| v.is_finite());
                drop |= !finite;
                let largest = if finite {
                    largest_eigenvalue(covariance, d)
                } else {
                    0.0
                };
                drop |= largest > spec.max_position_variance;
                drop |= time - version.last_seen > spec.max_time_without_update;
                drop
            })
            .collect()
    }

    /// `_split` of the filter's model: objects every hypothesis holds split off.
    fn split(&self, hypotheses: Vec<Hypothesis>, table: &Table) -> KernelResult<Vec<Cluster>> {
        split_with(hypotheses, |key| table.rate(key), self.tables.mht)
    }

    /// Every hypothesis weighted by the missed-detection likelihoods of its objects
    /// (`undetected`): `p(h | no detection) ∝ p(h) prod_{o in h} q_o`; a cluster with
    /// one hypothesis is unchanged.
    fn undetected(
        &self,
        clusters: Vec<Arc<Cluster>>,
        log_q: &KeyMap<Key, f64>,
        table: &Table,
    ) -> KernelResult<Vec<Arc<Cluster>>> {
        let mut result = Vec::with_capacity(clusters.len());
        for cluster in clusters {
            if cluster.hypotheses.len() == 1 {
                result.push(cluster);
                continue;
            }
            let mut merged = Merged::new();
            for h in &cluster.hypotheses {
                let mut terms = Vec::with_capacity(h.keys.len());
                for key in &h.keys {
                    terms.push(*log_q.get(key).ok_or_else(|| {
                        KernelError::Value(format!("no missed-detection term for version {key}"))
                    })?);
                }
                merged.add(h.keys.clone(), h.log_weight + fsum(terms), h.rate);
            }
            let hypotheses = prune(merged, self.tables.ratio, self.tables.max_hypotheses)?;
            if hypotheses.len() == cluster.hypotheses.len() && !common(&hypotheses) {
                result.push(Arc::new(Cluster {
                    hypotheses,
                    keys: cluster.keys.clone(),
                }));
            } else {
                result.extend(self.split(hypotheses, table)?.into_iter().map(Arc::new));
            }
        }
        Ok(result)
    }

    /// Objects removed from every hypothesis; hypotheses that become identical merge
    /// (`without`).
    fn without(
        &self,
        clusters: Vec<Arc<Cluster>>,
        gone: &KeySet<Key>,
        table: &Table,
    ) -> KernelResult<Vec<Arc<Cluster>>> {
        let mut result = Vec::with_capacity(clusters.len());
        for cluster in clusters {
            if !cluster.keys.iter().any(|k| gone.contains(k)) {
                result.push(cluster);
                continue;
            }
            let mut merged = Merged::new();
            let count = cluster.hypotheses.len();
            for h in &cluster.hypotheses {
                let mut rate = h.rate;
                let mut removed = 0.0;
                let mut any = false;
                for key in h.keys.iter().filter(|k| gone.contains(k)) {
                    // the specification's sum(): from 0, in key order
                    removed += table.rate(*key)?;
                    any = true;
                }
                if any {
                    rate = h.rate - removed;
                }
                let keys: Vec<Key> = h
                    .keys
                    .iter()
                    .copied()
                    .filter(|k| !gone.contains(k))
                    .collect();
                merged.add(keys, h.log_weight, rate);
            }
            let hypotheses = prune(merged, 0.0, count)?;
            result.extend(self.split(hypotheses, table)?.into_iter().map(Arc::new));
        }
        Ok(result)
    }

    /// What the scan (no sensor view) tells about where its source looked (`_coverage`).
    fn coverage(&self, measurements: &[Measurement]) -> ScanCoverage {
        let first = &measurements[0];
        let mut used: Vec<usize> = measurements.iter().map(|m| m.detector).collect();
        used.sort_unstable();
        used.dedup();
        let detectors: Vec<_> = used.iter().map(|&i| &self.tables.detectors[i]).collect();
        let reach = if detectors.iter().all(|d| d.range.is_some()) {
            detectors
                .iter()
                .filter_map(|d| d.range)
                .fold(None, |top: Option<f64>, r| {
                    Some(top.map_or(r, |t| if r > t { r } else { t }))
                })
        } else {
            None
        };
        let fixed = detectors.iter().all(|d| d.fixed);
        let mut sensor = first.sensor.clone();
        if fixed && sensor.is_none() && detectors.len() == 1 {
            sensor = detectors[0].position.clone();
        }
        ScanCoverage {
            source: first.source.clone(),
            positions: measurements
                .iter()
                .flat_map(|m| m.z.iter().copied())
                .collect(),
            dim: self.tables.dim,
            sensor,
            reach,
            fixed,
        }
    }

    /// Per detector of the scan, each predicted object's rate in the association weight
    /// of its detections (`_stream_rates`).
    fn stream_rates(
        &self,
        observed: &ObservedRates,
        predicted: &Predicted,
        measurements: &[Measurement],
        time: f64,
    ) -> Option<Vec<Option<Vec<f64>>>> {
        if !self.tables.observed_rates || measurements.is_empty() || predicted.is_empty() {
            return None;
        }
        let source = &measurements[0].source;
        let lineages: Vec<u64> = predicted.rows.iter().map(|r| r.version.lineage).collect();
        let base: Vec<f64> = predicted
            .rows
            .iter()
            .map(|r| self.tables.classes[r.version.cls].detection_frequency)
            .collect();
        let classes: Vec<&Name> = predicted
            .rows
            .iter()
            .map(|r| &self.tables.classes[r.version.cls].name)
            .collect();
        let unconfirmed: Vec<bool> = predicted
            .rows
            .iter()
            .map(|r| r.version.unconfirmed())
            .collect();
        let mut rates: Vec<Option<Vec<f64>>> = vec![None; self.tables.detectors.len()];
        for m in measurements {
            if rates[m.detector].is_none() {
                let detector = &self.tables.detectors[m.detector].name;
                rates[m.detector] = Some(observed.stream_rates(
                    (source, detector),
                    &lineages,
                    &base,
                    time,
                    Some(&classes),
                    Some(&unconfirmed),
                ));
            }
        }
        Some(rates)
    }

    /// Processes one scan: detections sharing a source and a time (`process_scan`).
    /// With `view` (where the sensor looked) the scan may be empty, and objects in view
    /// that it does not report lose existence.
    pub fn process_scan(
        &self,
        state: &State,
        measurements: &[Measurement],
        view: Option<&SensorView>,
    ) -> KernelResult<State> {
        let tables = &self.tables;
        let time = match (measurements.first(), view) {
            (Some(m), _) => m.time,
            (None, Some(v)) => v.time,
            (None, None) => return Ok(state.clone()),
        };
        let versions: Vec<Arc<Version>> =
            state.tracks.values().map(|e| e.version.clone()).collect();
        let mut predicted = predict(&versions, time, tables)?;
        let scan = if view.is_none() && !measurements.is_empty() {
            Some(self.coverage(measurements))
        } else {
            None
        };
        let inside = self.inside(&predicted);
        let (existence, log_q) = self.existence_at(state, &predicted, time, scan.as_ref(), &inside);
        // the predicted versions and, about, one updated version per detection
        let stored = predicted.len() + 2 * measurements.len();
        let mut table = Table {
            versions: KeyMap::with_capacity_and_hasher(stored, Default::default()),
            existence: KeyMap::with_capacity_and_hasher(stored, Default::default()),
        };
        for (row, &r) in predicted.rows.iter().zip(&existence) {
            table.add(row.version.clone(), r);
        }
        let mut clusters: Vec<Arc<Cluster>> = state.clusters.clone();
        if let Some(log_q) = &log_q {
            let by_key: KeyMap<Key, f64> = predicted
                .rows
                .iter()
                .zip(log_q)
                .map(|(row, &q)| (row.version.key, q))
                .collect();
            clusters = self.undetected(clusters, &by_key, &table)?;
        }
        let drop = self.leaving(&predicted, time, &existence, &inside);
        let mut existence = existence;
        if drop.iter().any(|&d| d) {
            let gone: KeySet<Key> = predicted
                .rows
                .iter()
                .zip(&drop)
                .filter(|(_, &d)| d)
                .map(|(row, _)| row.version.key)
                .collect();
            clusters = self.without(clusters, &gone, &table)?;
            let alive: Vec<usize> = (0..drop.len()).filter(|&i| !drop[i]).collect();
            existence = alive.iter().map(|&i| existence[i]).collect();
            predicted = predicted.subset(&alive);
        }
        let settle = if view.is_none() && tables.mht && tables.ratio > 0.0 {
            let settle: KeyMap<Key, f64> = clusters
                .iter()
                .filter(|c| c.hypotheses.len() == 1 && c.keys.len() == 1)
                .map(|c| (c.keys[0], c.hypotheses[0].log_weight))
                .collect();
            Some(settle)
        } else {
            None
        };
        let detection_rates = self.stream_rates(&state.observed, &predicted, measurements, time);
        let mut next_key = state.next_key;
        let options = association::options(
            &Inputs {
                tables,
                predicted: &predicted,
                measurements,
                existence: &existence,
                detection_rates: detection_rates.as_deref(),
                settle: settle.as_ref(),
                log_ratio: tables.log_ratio(),
            },
            &mut next_key,
        )?;
        let mut out_of_view: KeySet<u64> = KeySet::default();
        if let (Some(view), true) = (view, tables.mht) {
            let seen: KeySet<Key> = options
                .iter()
                .filter_map(|o| match o {
                    ScanOption::Detection(option) => {
                        Some(option.existing.iter().map(|u| u.old_key))
                    }
                    ScanOption::Settled { .. } => None,
                })
                .flatten()
                .collect();
            let (r_view, log_q_view) =
                self.looked_at(view, &predicted, &seen, &table, &state.observed)?;
            for (row, r) in predicted.rows.iter().zip(r_view) {
                table.existence.insert(row.version.key, r);
            }
            let by_key: KeyMap<Key, f64> = predicted
                .rows
                .iter()
                .zip(&log_q_view)
                .map(|(row, &q)| (row.version.key, q))
                .collect();
            clusters = self.undetected(clusters, &by_key, &table)?;
            // an object the view did not hold had no chance to be detected again
            for (i, row) in predicted.rows.iter().enumerate() {
                if !predicted.in_view_reaches(i, &view.view, 0.5)? {
                    out_of_view.insert(row.version.lineage);
                }
            }
        }
        let first_new = state.next_key;
        let expanded = self.expand_scan(clusters, &options, &mut table, first_new, next_key)?;
        next_key = expanded.next_key;
        let fresh: KeySet<Key> = expanded.fresh;
        let mut final_clusters: Vec<Arc<Cluster>> = expanded.clusters;
        if tables.merge_distance > 0.0 {
            for cluster in final_clusters.iter_mut().skip(expanded.untouched) {
                if cluster.hypotheses.len() > 1 {
                    let merged = merge_similar_in(
                        &cluster.keys,
                        &cluster.hypotheses,
                        &table.versions,
                        &table.existence,
                        tables.merge_distance,
                    )?;
                    if let Some(hypotheses) = merged {
                        if hypotheses.len() < cluster.hypotheses.len() {
                            *cluster = Arc::new(Cluster::of(hypotheses));
                        }
                    }
                }
            }
        }
        let referenced = key_union(final_clusters.iter().map(|c| c.keys.as_slice()));
        let mut tracks = LiteMap::with_capacity(referenced.len());
        for key in &referenced {
            let version = table.version(*key)?.clone();
            let existence = table.existence.get(key).copied().unwrap_or(1.0);
            let serial = match state.tracks.get(key) {
                Some(old) if Arc::ptr_eq(&old.version, &version) => old.serial,
                _ => next_serial(),
            };
            tracks.insert(
                *key,
                Entry {
                    version,
                    existence,
                    serial,
                },
            );
        }
        let mut observed = state.observed.clone();
        if (tables.observed_rates || tables.missed_detections)
            && (!measurements.is_empty() || view.is_some())
        {
            observed = Arc::new(self.observe(
                &state.observed,
                out_of_view,
                state,
                &options,
                measurements,
                view,
                &final_clusters,
                &table,
                &fresh,
                time,
            ));
        }
        Ok(State {
            clusters: final_clusters,
            tracks,
            time: Some(time),
            next_key,
            observed,
        })
    }

    /// Negative information of one scan with a sensor view (`looked_at`): the existence
    /// of every predicted version after the scan did not report it, and the log
    /// missed-detection likelihood of each. The detection probability is
    /// `P_D(class) P(in view)` (the view eroded by the margin of an object that stands
    /// still and that the view's source never reported), P_D the one the view's stream is
    /// observed to have once it has the evidence, else the class's; versions a detection
    /// of the scan gated (`seen`) are left to the association.
    fn looked_at(
        &self,
        view: &SensorView,
        predicted: &Predicted,
        seen: &KeySet<Key>,
        table: &Table,
        observed: &ObservedRates,
    ) -> KernelResult<(Vec<f64>, Vec<f64>)> {
        let tables = &self.tables;
        let spread = predicted.spread();
        let edges: Vec<f64> = predicted
            .rows
            .iter()
            .enumerate()
            .map(|(i, row)| {
                let never = !row.version.seen_by(&view.source);
                let margin = tables.classes[row.version.cls]
                    .region_margin
                    .iter()
                    .copied()
                    .fold(0.0, f64::max);
                let edge = np_minimum(margin, tables.gate_quantile * spread[i]);
                if never {
                    edge
                } else {
                    0.0 * edge
                }
            })
            .collect();
        let eroded = edges.iter().any(|&e| e != 0.0);
        let detection = if tables.observed_rates {
            let priors: BTreeMap<String, f64> = tables
                .classes
                .iter()
                .map(|c| (c.name.to_string(), c.detection_probability))
                .collect();
            match view.detector {
                Some(detector) => observed.detection_probabilities(
                    &view.source,
                    &tables.detectors[detector].name,
                    &priors,
                ),
                None => BTreeMap::new(),
            }
        } else {
            BTreeMap::new()
        };
        let mut r_new = Vec::with_capacity(predicted.len());
        let mut log_q = Vec::with_capacity(predicted.len());
        for (i, row) in predicted.rows.iter().enumerate() {
            let version = &row.version;
            let inside =
                predicted.in_view(i, &view.view, if eroded { Some(edges[i]) } else { None })?;
            let p = if seen.contains(&version.key) {
                0.0
            } else {
                let spec = &tables.classes[version.cls];
                let p_d = detection
                    .get(spec.name.as_ref())
                    .copied()
                    .unwrap_or(spec.detection_probability);
                p_d * if view.looks_at(version.lineage) {
                    1.0
                } else {
                    inside
                }
            };
            let r = table.existence.get(&version.key).copied().unwrap_or(1.0);
            let (r2, q) = missed(r, p);
            r_new.push(r2);
            log_q.push(q);
        }
        Ok((r_new, log_q))
    }

    /// Step 5 (`_expand_scan`): the scan's clusters, detection by detection
    /// (`crate::mhf::expansion`); the versions the expansion makes (births, copies
    /// that give a label up) enter the table.
    fn expand_scan(
        &self,
        clusters: Vec<Arc<Cluster>>,
        options: &[ScanOption],
        table: &mut Table,
        first_new: Key,
        next_key: Key,
    ) -> KernelResult<ExpandedScan> {
        let tables = &self.tables;
        // labels as small ids, as the algebra compares them
        let mut labels: BTreeMap<Name, u32> = BTreeMap::new();
        let mut label_id = |label: &Option<Name>| -> Option<u32> {
            label.as_ref().map(|l| {
                let next = labels.len() as u32;
                *labels.entry(l.clone()).or_insert(next)
            })
        };
        // the versions the options add to the table (updates, settled, new), room made once
        let adding: usize = options
            .iter()
            .map(|option| match option {
                ScanOption::Settled { .. } => 1,
                ScanOption::Detection(option) => option.existing.len() + 1,
            })
            .sum();
        table.versions.reserve(adding);
        table.existence.reserve(adding);
        let mut fresh: KeySet<Key> = KeySet::with_capacity_and_hasher(adding, Default::default());
        let mut new_versions: KeyMap<Key, Arc<Version>> =
            KeyMap::with_capacity_and_hasher(options.len(), Default::default());
        let mut scan_options = Vec::with_capacity(options.len());
        for option in options {
            match option {
                ScanOption::Settled {
                    old_key, version, ..
                } => {
                    table.add(version.clone(), 1.0);
                    fresh.insert(version.key);
                    scan_options.push(expansion::ScanOption::Settled {
                        old_key: *old_key,
                        updated: version.key,
                    });
                }
                ScanOption::Detection(option) => {
                    for update in &option.existing {
                        table.add(update.version.clone(), 1.0);
                        fresh.insert(update.version.key);
                    }
                    new_versions.insert(option.new_version.key, option.new_version.clone());
                    if !tables.mht {
                        table.add(option.new_version.clone(), 1.0);
                        fresh.insert(option.new_version.key);
                    }
                    let mut existing: Vec<expansion::Existing> = option
                        .existing
                        .iter()
                        .map(|u| expansion::Existing {
                            old_key: u.old_key,
                            updated: u.version.key,
                            log_num: u.log_num,
                            rate_change: u.rate_change,
                        })
                        .collect();
                    existing.sort_by_key(|e| e.old_key);
                    scan_options.push(expansion::ScanOption::Detection(
                        expansion::DetectionOptions {
                            label: label_id(&option.new_version.label),
                            clutter_rate: option.clutter_rate,
                            log_clutter: option.log_clutter,
                            new_key: option.new_version.key,
                            new_track_rate: option.new_version.rate,
                            new_rate: option.new_rate,
                            new_log: option.new_log,
                            presence: option
                                .presence
                                .iter()
                                .map(|p| expansion::Presence {
                                    key: p.key,
                                    rate: p.rate,
                                    log_num: p.log_num,
                                })
                                .collect(),
                            existing,
                        },
                    ));
                }
            }
        }
        let mut info: KeyMap<u64, expansion::TrackInfo> = KeyMap::with_capacity_and_hasher(
            table.versions.len() + new_versions.len(),
            Default::default(),
        );
        for (key, version) in table.versions.iter().chain(new_versions.iter()) {
            info.insert(
                *key,
                expansion::TrackInfo {
                    rate: version.rate,
                    label: label_id(&version.label),
                },
            );
        }
        let count = clusters.len();
        let expanded = expansion::expand_scan(expansion::Scan {
            settings: expansion::Settings {
                ratio: tables.ratio,
                max_hypotheses: tables.max_hypotheses,
                mht: tables.mht,
                log_label_error: tables.log_label_error,
            },
            tracks: info,
            first_new,
            next_key,
            clusters: clusters.into_iter().enumerate().collect(),
            cluster_count: count,
            options: scan_options,
        })?;
        // the versions the algebra made, in the order their keys were given
        for op in &expanded.ops {
            match *op {
                Op::Birth {
                    key,
                    from,
                    existence,
                } => {
                    let new = new_versions.get(&from).ok_or_else(|| {
                        KernelError::Value(format!("birth of unknown object {from}"))
                    })?;
                    let version = if key == from {
                        new.clone()
                    } else {
                        Arc::new(new.relabeled(key, new.label.clone()))
                    };
                    table.add(version, existence);
                    fresh.insert(key);
                }
                Op::Copy { key, from } => {
                    let source = table.version(from)?.clone();
                    let existence = table.existence.get(&from).copied().unwrap_or(1.0);
                    table.add(Arc::new(source.relabeled(key, None)), existence);
                    if fresh.contains(&from) {
                        fresh.insert(key);
                    }
                }
            }
        }
        Ok(ExpandedScan {
            untouched: expanded.untouched.len(),
            clusters: {
                let mut all: Vec<Arc<Cluster>> =
                    Vec::with_capacity(expanded.untouched.len() + expanded.clusters.len());
                all.extend(expanded.untouched_clusters);
                all.extend(expanded.clusters);
                all
            },
            next_key: expanded.next_key,
            fresh,
        })
    }

    /// The observed rates after the scan (`_observe`): per detector, which objects its
    /// detections updated or started in the most probable hypothesis, and which it
    /// started in the others (they see those too, but do not count them).
    #[allow(clippy::too_many_arguments)]
    fn observe(
        &self,
        observed: &ObservedRates,
        out_of_view: KeySet<u64>,
        before: &State,
        options: &[ScanOption],
        measurements: &[Measurement],
        view: Option<&SensorView>,
        final_clusters: &[Arc<Cluster>],
        table: &Table,
        fresh: &KeySet<Key>,
        time: f64,
    ) -> ObservedRates {
        let tables = &self.tables;
        let lineage_before = |key: Key| before.tracks.get(&key).map(|e| e.version.lineage);
        let mut detector_of: KeyMap<u64, usize> =
            KeyMap::with_capacity_and_hasher(2 * options.len(), Default::default());
        for option in options {
            let detector = measurements[option.row()].detector;
            match option {
                ScanOption::Settled { old_key, .. } => {
                    if let Some(lineage) = lineage_before(*old_key) {
                        detector_of.entry(lineage).or_insert(detector);
                    }
                }
                ScanOption::Detection(option) => {
                    detector_of
                        .entry(option.new_version.lineage)
                        .or_insert(detector);
                    for update in &option.existing {
                        if let Some(lineage) = lineage_before(update.old_key) {
                            detector_of.entry(lineage).or_insert(detector);
                        }
                    }
                }
            }
        }
        let existed: KeySet<u64> = before.tracks.values().map(|e| e.version.lineage).collect();
        let name = |detector: usize| -> Name { tables.detectors[detector].name.clone() };
        // by detector index while filling (no name compared per object), by name after
        let count = tables.detectors.len();
        let mut detected_by: Vec<Vec<u64>> = vec![Vec::new(); count];
        let mut born_by: Vec<Vec<u64>> = vec![Vec::new(); count];
        let mut born_elsewhere_by: Vec<Vec<u64>> = vec![Vec::new(); count];
        let mut alive: KeySet<u64> =
            KeySet::with_capacity_and_hasher(table.versions.len(), Default::default());
        let mut classes: KeyMap<u64, Name> =
            KeyMap::with_capacity_and_hasher(fresh.len(), Default::default());
        for cluster in final_clusters {
            for key in &cluster.keys {
                if let Some(version) = table.versions.get(key) {
                    alive.insert(version.lineage);
                }
            }
            let best = &cluster.hypotheses[0].keys;
            for key in &cluster.keys {
                if !fresh.contains(key) {
                    continue;
                }
                let Some(version) = table.versions.get(key) else {
                    continue;
                };
                let lineage = version.lineage;
                let Some(&by) = detector_of.get(&lineage) else {
                    continue;
                };
                if best.binary_search(key).is_ok() {
                    let target = if existed.contains(&lineage) {
                        &mut detected_by
                    } else {
                        &mut born_by
                    };
                    target[by].push(lineage);
                    classes.insert(lineage, tables.classes[version.cls].name.clone());
                } else if !existed.contains(&lineage) {
                    born_elsewhere_by[by].push(lineage);
                }
            }
        }
        let by_name = |lists: Vec<Vec<u64>>| -> LiteMap<Name, Vec<u64>> {
            lists
                .into_iter()
                .enumerate()
                .filter(|(_, lineages)| !lineages.is_empty())
                .map(|(detector, lineages)| (name(detector), lineages))
                .collect()
        };
        let (detected, born, born_elsewhere) = (
            by_name(detected_by),
            by_name(born_by),
            by_name(born_elsewhere_by),
        );
        let (source, scanned): (Name, BTreeSet<Name>) = match (measurements.first(), view) {
            (Some(first), _) => (first.source.clone(), {
                // the detectors by index first: a name per detector, not per detection
                let mut used: Vec<usize> = measurements.iter().map(|m| m.detector).collect();
                used.sort_unstable();
                used.dedup();
                used.into_iter().map(name).collect()
            }),
            (None, Some(view)) => (
                view.source.clone(),
                [name(view.detector.unwrap_or(tables.default_detector))]
                    .into_iter()
                    .collect(),
            ),
            (None, None) => (Arc::from(""), BTreeSet::new()),
        };
        let position = measurements.first().and_then(|m| m.sensor.clone());
        observed.after_scan(&ScanReport {
            source,
            time,
            detected,
            born,
            alive,
            position,
            classes: Some(classes),
            born_elsewhere,
            scanned: Some(scanned),
            out_of_view,
        })
    }
}

/// Step 5's result: the clusters (the untouched ones first, then the new ones), how
/// many are untouched, the next key and the versions that took a detection.
struct ExpandedScan {
    untouched: usize,
    clusters: Vec<Arc<Cluster>>,
    next_key: Key,
    fresh: KeySet<Key>,
}

/// Whether some object is held by every hypothesis (`_common`: the cluster splits).
fn common(hypotheses: &[Hypothesis]) -> bool {
    let Some(first) = hypotheses.first() else {
        return false;
    };
    first.keys.iter().any(|k| {
        hypotheses[1..]
            .iter()
            .all(|h| h.keys.binary_search(k).is_ok())
    })
}
