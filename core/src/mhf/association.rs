//! Per-scan association (`semwm/mhf/association.py`): gating, the updates, and every
//! detection's options with the log numerators of its priors times likelihoods.
//!
//! ```text
//! paper (paper 002 eqs. 5-8): clutter f_c / F, new f_new / F,
//!        existing f_e / F L_class exp(-1/2 delta^T R^-1 delta), delta = z - H x+
//! mht:   clutter f_c / V_c, births f_new / V (or an appearance relation's rate over
//!        its disc), one option "new or clutter"; an existing object o with existence
//!        r takes z with weight r f_e(o) L_class(o, z) N(z; H x-, S)
//! ```
//!
//! A labelled detection can update the object holding its label within `label_gate`
//! even outside the Mahalanobis gate, and any other explanation pays the prior
//! `label_error_rate` (paper 000 III-B made a likelihood). The specification's order is
//! kept everywhere it decides something: the pairs in row-major order (detection, then
//! object), one update batch per filter shape in order of first appearance, the keys of
//! the updated versions given in that order, then one key per detection for the object
//! it would start.

use std::sync::Arc;

use crate::error::KernelResult;
use crate::filters::batched;
use crate::filters::small::{inverse_and_log_det, mahalanobis_squared, quadratic_form};
use crate::mhf::classes::{self, numpy_sum};
use crate::mhf::hypotheses::{log_add, KeyMap, TIE};
use crate::mhf::measurement::Measurement;
use crate::mhf::predict::{conform, Predicted};
use crate::mhf::state::{FilterState, Key, Version};
use crate::mhf::tables::Tables;

const LOG_2PI: f64 = 1.8378770664093453;

/// An object a detection may update: its updated version, the log numerator of the
/// update and the change of f_existing (`existing`'s entries).
#[derive(Debug, Clone)]
pub struct Update {
    pub old_key: Key,
    pub version: Arc<Version>,
    pub log_num: f64,
    pub rate_change: f64,
}

/// An object whose presence makes a birth here likelier (eq. 4): its rate and log
/// numerator.
#[derive(Debug, Clone, Copy)]
pub struct Presence {
    pub key: Key,
    pub rate: f64,
    pub log_num: f64,
}

/// What one detection can be (`DetectionOptions`).
#[derive(Debug, Clone)]
pub struct DetectionOptions {
    /// The detection's row in the scan.
    pub row: usize,
    pub clutter_rate: f64,
    pub log_clutter: f64,
    /// The new object it would start.
    pub new_version: Arc<Version>,
    /// The base f_new and its log numerator.
    pub new_rate: f64,
    pub new_log: f64,
    /// In the specification's dict order.
    pub presence: Vec<Presence>,
    /// In the specification's dict order (the order the updates were made).
    pub existing: Vec<Update>,
}

/// One detection of the scan, as the association leaves it.
#[derive(Debug, Clone)]
pub enum ScanOption {
    /// `SettledUpdate`: it updates one object for certain.
    Settled {
        row: usize,
        old_key: Key,
        version: Arc<Version>,
    },
    Detection(DetectionOptions),
}

impl ScanOption {
    pub fn row(&self) -> usize {
        match self {
            ScanOption::Settled { row, .. } => *row,
            ScanOption::Detection(option) => option.row,
        }
    }
}

fn log_or_minus_inf(value: f64) -> f64 {
    if value > 0.0 {
        value.ln()
    } else {
        f64::NEG_INFINITY
    }
}

/// `numpy.logaddexp` of two floats.
pub fn logaddexp(a: f64, b: f64) -> f64 {
    if a == b {
        return a + std::f64::consts::LN_2;
    }
    let tmp = a - b;
    if tmp > 0.0 {
        a + (-tmp).exp().ln_1p()
    } else if tmp <= 0.0 {
        b + tmp.exp().ln_1p()
    } else {
        tmp // NaN
    }
}

/// `sqrt(offset @ offset)` of two positions.
fn distance(a: &[f64], b: &[f64]) -> f64 {
    let mut total = 0.0;
    for (x, y) in a.iter().zip(b) {
        total += (x - y) * (x - y);
    }
    total.sqrt()
}

/// The inputs of one scan's association.
pub struct Inputs<'a> {
    pub tables: &'a Tables,
    pub predicted: &'a Predicted,
    pub measurements: &'a [Measurement],
    /// Each predicted object's existence (`mht`).
    pub existence: &'a [f64],
    /// Per detector (by index), each predicted object's f_existing in the weight of
    /// that detector's detections (`None`: its class's).
    pub detection_rates: Option<&'a [Option<Vec<f64>>]>,
    /// Object key -> log weight of its cluster's only hypothesis, for the objects alone
    /// and certain in theirs (`None`: no settled updates).
    pub settle: Option<&'a KeyMap<Key, f64>>,
    pub log_ratio: f64,
}

/// Every detection's options against the predicted objects (`Associator.options`);
/// `next_key` gives the keys (updated versions first, then one per detection).
pub fn options(inputs: &Inputs<'_>, next_key: &mut Key) -> KernelResult<Vec<ScanOption>> {
    let tables = inputs.tables;
    let measurements = inputs.measurements;
    let existing = existing(inputs, next_key)?;
    let spread_uniform = if tables.mht { -tables.log_volume } else { 0.0 };
    let settled = match inputs.settle {
        Some(settle) => settled_rows(inputs, &existing, settle),
        None => vec![None; measurements.len()],
    };
    let mut result = Vec::with_capacity(measurements.len());
    for (j, (m, found)) in measurements.iter().zip(existing).enumerate() {
        if let Some((old_key, version)) = settled[j].clone() {
            *next_key += 1; // the key its new object would have had
            result.push(ScanOption::Settled {
                row: j,
                old_key,
                version,
            });
            continue;
        }
        let resolved = &tables.classes[m.cls];
        let mut base_rate = resolved.new_frequency;
        let mut base_log = log_or_minus_inf(base_rate) + spread_uniform;
        let mut presence: Vec<Presence> = Vec::new();
        for relation in &resolved.appearance {
            let log_num = relation.log_num;
            for known in &relation.known {
                if distance(&m.z, known) <= relation.max_distance && log_num > base_log {
                    base_rate = relation.frequency;
                    base_log = log_num;
                }
            }
            let reach = relation.max_distance * relation.max_distance;
            for (i, row) in inputs.predicted.rows.iter().enumerate() {
                if !relation.covered[row.version.cls] {
                    continue;
                }
                let position = inputs.predicted.position(i);
                let mut squared = 0.0;
                for (a, b) in position.iter().zip(&m.z) {
                    squared += (a - b) * (a - b);
                }
                if squared > reach {
                    continue;
                }
                let key = row.version.key;
                match presence.iter_mut().find(|p| p.key == key) {
                    Some(p) if log_num > p.log_num => {
                        p.rate = relation.frequency;
                        p.log_num = log_num;
                    }
                    Some(_) => {}
                    None if log_num > f64::NEG_INFINITY => presence.push(Presence {
                        key,
                        rate: relation.frequency,
                        log_num,
                    }),
                    None => {}
                }
            }
        }
        presence.retain(|p| p.log_num > base_log);
        let reported_filter = &tables.classes[m.cls];
        let (m_modes, m_size) = (reported_filter.filter.modes, reported_filter.filter.state);
        let mut x = vec![0.0; m_modes * m_size];
        for mode in 0..m_modes {
            x[mode * m_size..mode * m_size + tables.dim].copy_from_slice(&m.z);
        }
        let mut state = FilterState {
            modes: m_modes,
            size: m_size,
            x,
            p: reported_filter.initial_covariance.repeat(m_modes),
            mu: reported_filter.initial_mode_probabilities.clone(),
        };
        let (class_probs, cls) = if tables.mht {
            let probs = classes::initial(tables, m.detector, m.cls);
            let cls = classes::published(tables, &probs);
            if cls != m.cls {
                state = conform(&state, tables, cls);
            }
            (probs, cls)
        } else {
            (classes::point(tables, m.cls), m.cls)
        };
        let key = *next_key;
        *next_key += 1;
        let new_version = Arc::new(Version {
            key,
            lineage: m.seq,
            cls,
            label: m.label.clone(),
            state: Arc::new(state),
            time: m.time,
            last_seen: m.time,
            created: m.time,
            rate: tables.classes[cls].detection_frequency,
            class_probs: class_probs.into(),
            sources: Arc::from([m.source.clone()]),
        });
        let density = if tables.mht {
            tables.detectors[m.detector].clutter_log_density
        } else {
            0.0
        };
        result.push(ScanOption::Detection(DetectionOptions {
            row: j,
            clutter_rate: m.clutter_rate,
            log_clutter: log_or_minus_inf(m.clutter_rate) + density,
            new_version,
            new_rate: base_rate,
            new_log: base_log,
            presence,
            existing: found,
        }));
    }
    Ok(result)
}

/// The detections that certainly update one object (`Associator._settled`), by row.
fn settled_rows(
    inputs: &Inputs<'_>,
    existing: &[Vec<Update>],
    settle: &KeyMap<Key, f64>,
) -> Vec<Option<(Key, Arc<Version>)>> {
    let tables = inputs.tables;
    let measurements = inputs.measurements;
    let mut result = vec![None; measurements.len()];
    if settle.is_empty() || !tables.mht {
        return result;
    }
    if measurements
        .iter()
        .any(|m| m.label.is_some() || !tables.classes[m.cls].appearance.is_empty())
    {
        return result;
    }
    let mut gated: KeyMap<Key, usize> = KeyMap::default();
    for found in existing {
        for update in found {
            *gated.entry(update.old_key).or_insert(0) += 1;
        }
    }
    let spread_uniform = -tables.log_volume;
    for (j, (m, found)) in measurements.iter().zip(existing).enumerate() {
        let [update] = found.as_slice() else {
            continue;
        };
        let Some(&log_norm) = settle.get(&update.old_key) else {
            continue;
        };
        if gated[&update.old_key] != 1 {
            continue;
        }
        let log_update = log_norm + update.log_num;
        if log_update == f64::NEG_INFINITY {
            continue;
        }
        let log_clutter =
            log_or_minus_inf(m.clutter_rate) + tables.detectors[m.detector].clutter_log_density;
        let new_log = log_or_minus_inf(tables.classes[m.cls].new_frequency) + spread_uniform;
        if log_norm + log_add(log_clutter, new_log) >= log_update + inputs.log_ratio - TIE {
            continue; // "new object or clutter" survives eq. (3): the general path
        }
        result[j] = Some((update.old_key, update.version.clone()));
    }
    result
}

/// `L_class` of a (detection, object) pair (`_class_likelihoods`): `mht`:
/// `sum_c p_o(c) L(C(z) | c)` (`reported`: the detection's `L(C(z) | c)`); `paper`:
/// eq. (8).
fn class_likelihood(tables: &Tables, reported: &[f64], m: &Measurement, version: &Version) -> f64 {
    if tables.mht {
        let mut total = 0.0;
        for (l, p) in reported.iter().zip(version.class_probs.iter()) {
            total += l * p;
        }
        total
    } else {
        let k = tables.class_count();
        tables.class_likelihood[version.cls * k + m.cls]
    }
}

/// The objects (rows) a detection at `z` may pair with, in no order: those whose first
/// coordinate lies within `radius` of `z`'s (`order` sorts the rows by it, `first`
/// holds the sorted coordinates). A superset of the pairs the cheap bound passes (its
/// radius is the largest that bound allows), so the exact test decides as the
/// specification's dense test does; the pairs it passes are then put in row order.
fn window(order: &[usize], first: &[f64], z: f64, radius: f64, out: &mut Vec<usize>) {
    out.clear();
    let reach = radius * (1.0 + 1e-9) + 1e-12;
    let low = first.partition_point(|&x| x < z - reach);
    let high = first.partition_point(|&x| x <= z + reach);
    out.extend_from_slice(&order[low..high]);
}

/// Gates every (detection, object) pair and updates the pairs that pass
/// (`Associator._existing`): per detection, its updates in the order they were made.
fn existing(inputs: &Inputs<'_>, next_key: &mut Key) -> KernelResult<Vec<Vec<Update>>> {
    let tables = inputs.tables;
    let predicted = inputs.predicted;
    let measurements = inputs.measurements;
    let (d, t) = (tables.dim, predicted.len());
    let mut found: Vec<Vec<Update>> = vec![Vec::new(); measurements.len()];
    if t == 0 || measurements.is_empty() {
        return Ok(found);
    }
    let mht = tables.mht;
    let timed = measurements.iter().any(|m| m.time_std > 0.0);
    let has_labels = mht && measurements.iter().any(|m| m.label.is_some());
    let label_reach = tables.label_gate * tables.label_gate;
    let trace_p: Vec<f64> = (0..t)
        .map(|i| {
            let p = predicted.covariance(i);
            (0..d).map(|a| p[a * d + a]).sum()
        })
        .collect();
    let speed2: Vec<f64> = if timed {
        (0..t)
            .map(|i| predicted.velocity(i).iter().map(|v| v * v).sum())
            .collect()
    } else {
        Vec::new()
    };
    // the pairs that pass the cheap bound (or hold the detection's label), row-major:
    // d^2 <= gate lambda_max(S) <= gate trace(S), and likelihood > 0
    struct Pair {
        j: usize,
        i: usize,
        labelled: bool,
        likelihood: f64,
    }
    let mut pairs: Vec<Pair> = Vec::new();
    let gated = tables.gate.is_finite();
    // rows sorted by their first coordinate, for the unlabelled detections' windows
    let mut order: Vec<usize> = (0..t).collect();
    order.sort_by(|&a, &b| predicted.position(a)[0].total_cmp(&predicted.position(b)[0]));
    let first: Vec<f64> = order.iter().map(|&i| predicted.position(i)[0]).collect();
    let widest = trace_p.iter().copied().fold(0.0, f64::max);
    let fastest = speed2.iter().copied().fold(0.0, f64::max);
    let mut rows: Vec<usize> = Vec::with_capacity(t);
    for (j, m) in measurements.iter().enumerate() {
        let trace_r: f64 = (0..d).map(|a| m.r[a * d + a]).sum();
        let time_var = m.time_std * m.time_std;
        let reported: &[f64] = if mht {
            classes::likelihood(tables, m.detector, m.cls)
        } else {
            &[]
        };
        let first_of_row = pairs.len();
        let dense = !gated || (has_labels && m.label.is_some());
        if dense {
            rows.clear();
            rows.extend(0..t);
        } else {
            let radius = (tables.gate * (widest + trace_r + time_var * fastest)).sqrt();
            if radius.is_nan() {
                rows.clear();
                rows.extend(0..t);
            } else {
                window(&order, &first, m.z[0], radius, &mut rows);
            }
        }
        for &i in &rows {
            let position = predicted.position(i);
            let mut squared = 0.0;
            for (z, x) in m.z.iter().zip(position) {
                let diff = z - x;
                squared += diff * diff;
            }
            let labelled = has_labels
                && m.label.is_some()
                && predicted.rows[i].version.label == m.label
                && squared <= label_reach;
            let mut near = true;
            if gated {
                let mut bound = tables.gate * (trace_p[i] + trace_r);
                if timed {
                    bound += tables.gate * time_var * speed2[i];
                }
                near = squared <= bound || labelled;
            }
            if !near {
                continue;
            }
            let likelihood = class_likelihood(tables, reported, m, &predicted.rows[i].version);
            if likelihood > 0.0 {
                pairs.push(Pair {
                    j,
                    i,
                    labelled,
                    likelihood,
                });
            }
        }
        // row-major order: a window's rows came by coordinate (a few pass; sort those)
        pairs[first_of_row..].sort_unstable_by_key(|pair| pair.i);
    }
    if pairs.is_empty() {
        return Ok(found);
    }
    // the Mahalanobis gate with the timing noise R' = R + sigma_t^2 v v^T (a pair's own
    // R' only with timing noise: else the detection's R, not copied)
    let mut passed: Vec<(Pair, Option<Vec<f64>>)> = Vec::with_capacity(pairs.len());
    let (mut residual, mut s) = ([0.0; 3], [0.0; 9]);
    for pair in pairs {
        let m = &measurements[pair.j];
        let timing = if timed {
            let mut r = m.r.to_vec();
            let v = predicted.velocity(pair.i);
            let sigma2 = m.time_std * m.time_std;
            for a in 0..d {
                for b in 0..d {
                    r[a * d + b] += sigma2 * v[a] * v[b];
                }
            }
            Some(r)
        } else {
            None
        };
        let r = timing.as_deref().unwrap_or(&m.r);
        let position = predicted.position(pair.i);
        let covariance = predicted.covariance(pair.i);
        for a in 0..d {
            residual[a] = m.z[a] - position[a];
        }
        for k in 0..d * d {
            s[k] = covariance[k] + r[k];
        }
        let d2 = mahalanobis_squared(&residual[..d], &s[..d * d], d)?;
        if d2 <= tables.gate || pair.labelled {
            passed.push((pair, timing));
        }
    }
    // one update batch per filter shape, in order of first appearance
    let mut shapes: Vec<((usize, usize), Vec<usize>)> = Vec::new();
    for (p, (pair, _)) in passed.iter().enumerate() {
        let shape = predicted.rows[pair.i].shape();
        match shapes.iter_mut().find(|(s, _)| *s == shape) {
            Some((_, members)) => members.push(p),
            None => shapes.push((shape, vec![p])),
        }
    }
    for (_, members) in shapes {
        for p in members {
            let (pair, timing) = &passed[p];
            let (i, j) = (pair.i, pair.j);
            let m = &measurements[j];
            let r: &[f64] = timing.as_deref().unwrap_or(&m.r);
            let row = &predicted.rows[i];
            let old = &row.version;
            let (modes, size) = row.shape();
            let mut x = row.x().to_vec();
            let mut covariance = row.p().to_vec();
            let mut mu = row.mu().to_vec();
            let mut log_lik =
                batched::update(&mut x, &mut covariance, &mut mu, &m.z, r, modes, size, d)?;
            if !mht {
                // paper 002 eq. (8): exp(-1/2 delta^T R^-1 delta) of the updated position
                let mut mean = vec![0.0; size];
                let mut full = vec![0.0; size * size];
                batched::combine(&x, &covariance, &mu, modes, size, &mut mean, &mut full);
                let delta: Vec<f64> = (0..d).map(|a| m.z[a] - mean[a]).collect();
                log_lik = -0.5 * mahalanobis_squared(&delta, r, d)?;
            } else if pair.labelled {
                log_lik = label_robust(log_lik, inputs, i, &m.z, r)?;
            }
            let (class_probs, refined): (Arc<[f64]>, usize) = if mht {
                let reported = classes::likelihood(tables, m.detector, m.cls);
                let mut posterior: Arc<[f64]> = old
                    .class_probs
                    .iter()
                    .zip(reported)
                    .map(|(p, l)| p * l)
                    .collect();
                let total = numpy_sum(&posterior);
                match Arc::get_mut(&mut posterior) {
                    Some(values) => values.iter_mut().for_each(|value| *value /= total),
                    // not reached (made just above, so not shared), but correct if it were
                    None => posterior = posterior.iter().map(|value| value / total).collect(),
                }
                let refined = classes::published(tables, &posterior);
                (posterior, refined)
            } else {
                let k = tables.class_count();
                let refined = tables.most_specific[old.cls * k + m.cls].unwrap_or(old.cls);
                (classes::point(tables, refined).into(), refined)
            };
            let mut state = FilterState {
                modes,
                size,
                x,
                p: covariance,
                mu,
            };
            if refined != old.cls {
                state = conform(&state, tables, refined);
            }
            let rate = tables.classes[refined].detection_frequency;
            let key = *next_key;
            *next_key += 1;
            let version = Arc::new(Version {
                key,
                lineage: old.lineage,
                cls: refined,
                label: m.label.clone().or_else(|| old.label.clone()),
                state: Arc::new(state),
                time: m.time,
                last_seen: m.time,
                created: old.created,
                rate,
                class_probs,
                sources: old.sources_with(&m.source),
            });
            let f_existing = match inputs.detection_rates {
                Some(rates) => match &rates[m.detector] {
                    Some(values) => values[i],
                    None => old.rate,
                },
                None => old.rate,
            };
            let mut log_num = log_or_minus_inf(f_existing) + pair.likelihood.ln() + log_lik;
            if mht {
                if !inputs.existence.is_empty() {
                    log_num += log_or_minus_inf(inputs.existence[i]);
                }
                if m.label.is_some() && old.label.is_some() && old.label != m.label {
                    log_num += tables.log_label_error;
                }
            }
            found[j].push(Update {
                old_key: old.key,
                version,
                log_num,
                rate_change: rate - old.rate,
            });
        }
    }
    Ok(found)
}

/// For a detection and the object holding its label: the likelihood mixed with a wide
/// component (standard deviation `label_gate / 3` per axis), so that a robot's own
/// precise report far from its lagging estimate still fits it (`_label_robust`).
fn label_robust(
    log_lik: f64,
    inputs: &Inputs<'_>,
    i: usize,
    z: &[f64],
    r: &[f64],
) -> KernelResult<f64> {
    let tables = inputs.tables;
    let d = tables.dim;
    let wide_var = (tables.label_gate / 3.0).powi(2);
    let covariance = inputs.predicted.covariance(i);
    let position = inputs.predicted.position(i);
    let mut s = vec![0.0; d * d];
    for a in 0..d {
        for b in 0..d {
            s[a * d + b] =
                covariance[a * d + b] + r[a * d + b] + if a == b { wide_var } else { 0.0 };
        }
    }
    let delta: Vec<f64> = (0..d).map(|a| z[a] - position[a]).collect();
    let mut inverse = vec![0.0; d * d];
    let log_det = inverse_and_log_det(&s, d, &mut inverse)?;
    let log_wide = -0.5 * (quadratic_form(&delta, &inverse, d) + log_det + d as f64 * LOG_2PI);
    Ok(logaddexp(log_lik + 0.9_f64.ln(), log_wide + 0.1_f64.ln()))
}
