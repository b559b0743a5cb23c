//! Confidence of objects (paper 004 Section IV, Fig. 5), as `semwm/confidence.py` keeps
//! it, which is the specification: each lineage's confidence `c` in [0, 1], set to its
//! detector's `confidence` by a detection (in the most probable hypothesis that holds
//! it), decaying while it is not seen,
//!
//! ```text
//! c <- c exp(-lambda dt) exp(-(lambda_look - lambda) min(look, MAX_LOOK)) exp(-kappa moved)
//! ```
//!
//! with the class's `confidence_decay` lambda, its `looking_decay` while a view held it
//! and did not report it, and `confidence_decay_distance` kappa per metre its observer
//! moved.

use std::collections::BTreeMap;
use std::sync::Arc;

use crate::error::KernelResult;
use crate::mhf::hypotheses::{KeyMap, KeySet};
use crate::mhf::measurement::SensorView;
use crate::mhf::predict::predict;
use crate::mhf::rates::Name;
use crate::mhf::state::{State, Version};
use crate::mhf::tables::Tables;

/// s: the longest interval one scan's look counts for.
pub const MAX_LOOK: f64 = 1.0;

/// Each lineage's confidence at a time, and each source's last sensor position and last
/// scan time (`ConfidenceBook`).
#[derive(Debug, Clone, Default)]
pub struct Book {
    pub values: KeyMap<u64, (f64, f64)>,
    pub poses: BTreeMap<Name, (f64, f64)>,
    pub scans: BTreeMap<Name, f64>,
}

/// Each lineage's version in the most probable hypothesis that holds it
/// (`representatives`), in the order the specification meets them.
pub fn representatives(state: &State) -> Vec<(u64, Arc<Version>)> {
    let mut chosen: Vec<(u64, Arc<Version>)> = Vec::with_capacity(state.tracks.len());
    let mut known: KeySet<u64> =
        KeySet::with_capacity_and_hasher(state.tracks.len(), Default::default());
    let version = |key: &u64| &state.tracks[key].version;
    for cluster in &state.clusters {
        if cluster.hypotheses.len() == 1 {
            for key in &cluster.hypotheses[0].keys {
                let v = version(key);
                if known.insert(v.lineage) {
                    chosen.push((v.lineage, v.clone()));
                }
            }
            continue;
        }
        let mut pending: KeySet<u64> =
            KeySet::with_capacity_and_hasher(cluster.keys.len(), Default::default());
        pending.extend(
            cluster
                .keys
                .iter()
                .map(|key| version(key).lineage)
                .filter(|lineage| !known.contains(lineage)),
        );
        for h in &cluster.hypotheses {
            for key in &h.keys {
                let v = version(key);
                if pending.remove(&v.lineage) {
                    known.insert(v.lineage);
                    chosen.push((v.lineage, v.clone()));
                }
            }
            if pending.is_empty() {
                break;
            }
        }
    }
    chosen
}

/// The book after one scan (`advance`; `state` is the filter after it): `detectors`, the
/// scan's detections' detectors; `source`, the view's source as the specification has it
/// (`None` when the view names none).
pub fn advance(
    book: &Book,
    state: &State,
    detectors: &[usize],
    view: Option<&SensorView>,
    source: Option<&Name>,
    tables: &Tables,
) -> KernelResult<Book> {
    let Some(time) = state.time else {
        return Ok(book.clone());
    };
    let chosen = representatives(state);
    let set_to = detectors
        .iter()
        .map(|&d| tables.detectors[d].confidence)
        .fold(None, |top: Option<f64>, c| {
            Some(top.map_or(c, |t| if c > t { c } else { t }))
        })
        .unwrap_or(1.0);
    let mut looked: KeySet<u64> = KeySet::default();
    if let Some(view) = view {
        let unseen: Vec<Arc<Version>> = chosen
            .iter()
            .filter(|(_, v)| v.last_seen < time)
            .map(|(_, v)| v.clone())
            .collect();
        if !unseen.is_empty() {
            let predicted = predict(&unseen, time, tables)?;
            for (i, v) in unseen.iter().enumerate() {
                if predicted.in_view_reaches(i, &view.view, 0.5)? || view.looks_at(v.lineage) {
                    looked.insert(v.lineage);
                }
            }
        }
    }
    let mut moved = 0.0;
    let mut poses = book.poses.clone();
    let mut scans = book.scans.clone();
    let mut looked_for: Option<f64> = None;
    if let (Some(view), Some(source)) = (view, source) {
        let here = (view.view.position[0], view.view.position[1]);
        if let Some(before) = poses.get(source) {
            moved = (before.0 - here.0).hypot(before.1 - here.1);
        }
        poses.insert(source.clone(), here);
        if let Some(&last) = scans.get(source) {
            looked_for = Some(MAX_LOOK.min((time - last).max(0.0)));
        }
    }
    if let Some(source) = source {
        scans.insert(source.clone(), time);
    }
    let mut values: KeyMap<u64, (f64, f64)> =
        KeyMap::with_capacity_and_hasher(chosen.len(), Default::default());
    for (lineage, version) in &chosen {
        let spec = &tables.classes[version.cls];
        let entry = book.values.get(lineage);
        let seen = version.last_seen >= time;
        let Some(&(mut value, since)) = entry.filter(|_| !seen) else {
            values.insert(*lineage, (if seen { set_to } else { 1.0 }, time));
            continue;
        };
        value *= (-spec.confidence_decay * (time - since).max(0.0)).exp();
        if looked.contains(lineage) {
            let look = looked_for.unwrap_or((time - since).max(0.0));
            let extra = (spec.looking_decay - spec.confidence_decay).max(0.0);
            value *= (-extra * look.min(MAX_LOOK)).exp();
        }
        value *= (-spec.confidence_decay_distance * moved).exp();
        values.insert(*lineage, (value, time));
    }
    Ok(Book {
        values,
        poses,
        scans,
    })
}
