//! The published world of a state, as `semwm/world.py` computes it for its ids
//! (`WorldModel._current`, `_stored_summaries`, `_same_objects`, `_coinciding`), which is
//! the specification: each object's marginal existence over the hypotheses, the version
//! shown for it, and lineages that are one physical object grouped.
//!
//! ```text
//! r(l) = sum_h p(h) sum_{v in h, lineage(v) = l} r_v P(v inside the region)
//! 4 D_B = delta^T (P_a + P_b)^-1 delta + 2 ln det((P_a + P_b)/2) / sqrt(det P_a det P_b)
//! ```
//!
//! Lineages whose estimates coincide (`4 D_B <= 1`), of compatible classes, that the most
//! probable hypothesis does not hold both as shown, are one object whose existence is
//! the sum of theirs (at most 1).

use std::sync::Arc;

use crate::error::KernelResult;
use crate::filters::small::{mahalanobis_squared, slogdet};
use crate::mhf::existence::inside_probability;
use crate::mhf::filter::Filter;
use crate::mhf::hypotheses::{fsum, KeyMap, KeySet, TIE};
use crate::mhf::predict::{predict, Predicted};
use crate::mhf::state::{Key, State, Version};
use crate::mhf::tables::{ClassId, Tables};

/// 4 x the Bhattacharyya distance under which two lineages' estimates coincide.
pub const SAME_OBJECT_GATE: f64 = 1.0;
/// Lineages less likely than this are not grouped.
pub const GROUPING_FLOOR: f64 = 1e-3;

/// A stored version's combined position `d` and covariance `d x d` (no prediction, and
/// no spread of the modes' means: `_stored_positions`) and its probability of being
/// inside the region widened by its class's margins.
#[derive(Debug, Clone)]
pub struct Summary {
    pub position: Vec<f64>,
    pub covariance: Vec<f64>,
    pub inside: f64,
}

/// Summaries of the versions a state held, by serial, kept from one call of [`current`]
/// to the next (`WorldModel._summaries`): a version not changed since is not summarised
/// again.
pub type Summaries = KeyMap<u64, Arc<Summary>>;

/// `_stored_summaries` of one version.
pub fn summary(version: &Version, tables: &Tables) -> Summary {
    summary_as(version, version.cls, tables)
}

/// [`summary`] of a version with the region margins of class `cls` (a version of
/// another knowledge's state names its class by another index).
fn summary_as(version: &Version, cls: ClassId, tables: &Tables) -> Summary {
    let d = tables.dim;
    let s = &version.state;
    let (m, n) = (s.modes, s.size);
    let mut position = vec![0.0; d];
    let mut covariance = vec![0.0; d * d];
    if m == 1 {
        position.copy_from_slice(&s.x[..d]);
        for a in 0..d {
            for b in 0..d {
                covariance[a * d + b] = s.p[a * n + b];
            }
        }
    } else {
        for (a, value) in position.iter_mut().enumerate() {
            let mut total = 0.0;
            for j in 0..m {
                total += s.mu[j] * s.x[j * n + a];
            }
            *value = total;
        }
        for a in 0..d {
            for b in 0..d {
                let mut total = 0.0;
                for j in 0..m {
                    total += s.mu[j] * s.p[j * n * n + a * n + b];
                }
                covariance[a * d + b] = total;
            }
        }
    }
    let inside = match &tables.region {
        None => 1.0,
        Some(region) => {
            let low: Vec<f64> = region.iter().map(|(a, _)| *a).collect();
            let high: Vec<f64> = region.iter().map(|(_, b)| *b).collect();
            let margin = &tables.classes[cls].region_margin;
            inside_probability(&position, &covariance, &low, &high, Some(margin))
        }
    };
    Summary {
        position,
        covariance,
        inside,
    }
}

/// `WorldModel._may_return`: whether an object lost from the published world (its
/// version, of class `cls` of `tables`) may come back under its id: its stored position
/// ([`summary`]) inside the region, widened by its class's margins, with probability at
/// least 1/2, and not within reach of a target its class leaves by (a disappearance
/// relation: someone coming in there is someone else).
pub fn may_return(version: &Version, cls: ClassId, tables: &Tables) -> bool {
    let summary = summary_as(version, cls, tables);
    if summary.inside < 0.5 {
        return false;
    }
    // `any` of the specification's `near <= max_distance` (a NaN distance is not near)
    !tables.classes[cls].leave_relations.iter().any(|relation| {
        let squared: f64 = summary
            .position
            .iter()
            .zip(&relation.target)
            .map(|(x, t)| (x - t) * (x - t))
            .sum();
        squared.sqrt() <= relation.max_distance
    })
}

/// One object's marginal existence and the version shown for it (`_Marginal`).
#[derive(Debug, Clone)]
pub struct Marginal {
    pub lineage: u64,
    pub existence: f64,
    pub key: Key,
}

/// Whether two Gaussian position estimates are one object (`_coinciding`): their
/// Bhattacharyya distance is at most `SAME_OBJECT_GATE / 4`.
pub fn coinciding(delta: &[f64], pa: &[f64], pb: &[f64], d: usize) -> bool {
    let total: Vec<f64> = pa.iter().zip(pb).map(|(a, b)| a + b).collect();
    let d2 = mahalanobis_squared(delta, &total, d).unwrap_or(f64::NAN);
    let half: Vec<f64> = total.iter().map(|v| 0.5 * v).collect();
    let (_, log_det_mean) = slogdet(&half, d);
    let (_, log_det_a) = slogdet(pa, d);
    let (_, log_det_b) = slogdet(pb, d);
    let spread = 2.0 * log_det_mean - log_det_a - log_det_b;
    d2 + spread <= SAME_OBJECT_GATE
}

/// Each lineage's existence summed over the versions of it a cluster's hypotheses hold
/// (`totals` in `_current` and `_marginals`), in order of first appearance, and the
/// version shown for it: the first in which it is present (existence in the region at
/// least `floor`), not a stale one that left the region long ago; else its first.
struct LineageTotals {
    floor: f64,
    /// In order of first appearance: the lineage, its total, the version shown and
    /// whether that version is one in which it is present.
    totals: Vec<LineageTotal>,
    /// Each lineage's row in `totals`.
    at: KeyMap<u64, usize>,
}

struct LineageTotal {
    lineage: u64,
    total: f64,
    shown: Key,
    present: bool,
}

impl LineageTotals {
    /// Room for `lineages` without growing.
    fn new(floor: f64, lineages: usize) -> LineageTotals {
        LineageTotals {
            floor,
            totals: Vec::with_capacity(lineages),
            at: KeyMap::with_capacity_and_hasher(lineages, Default::default()),
        }
    }

    /// Version `key` of `lineage`, of probability mass `p`, present (existence times
    /// the probability of being in the region) with `present`.
    fn add(&mut self, lineage: u64, key: Key, p: f64, present: f64) {
        let row = match self.at.get(&lineage) {
            Some(&i) => {
                let row = &mut self.totals[i];
                row.total += p * present;
                row
            }
            None => {
                let i = self.totals.len();
                self.at.insert(lineage, i);
                self.totals.push(LineageTotal {
                    lineage,
                    total: 0.0 + p * present,
                    shown: key,
                    present: false,
                });
                &mut self.totals[i]
            }
        };
        if present >= self.floor && !row.present {
            row.present = true;
            row.shown = key;
        }
    }

    /// `(lineage, total, key shown)` in order of first appearance.
    fn rows(&self) -> impl Iterator<Item = (u64, f64, Key)> + '_ {
        self.totals
            .iter()
            .map(|row| (row.lineage, row.total, row.shown))
    }
}

/// The published world at the state's time (`WorldModel._current`): `(lineage, key)` of
/// each object shown, in the order the specification's dict holds them. `shown`: the
/// lineages published now; `ids`: their ids (to keep ids stable when lineages group).
pub fn current(
    state: &State,
    tables: &Tables,
    shown: &KeySet<u64>,
    ids: &KeyMap<u64, i64>,
    cache: &mut Summaries,
) -> Vec<(u64, Key)> {
    let version = |key: Key| &state.tracks[&key].version;
    if !tables.mht {
        // the most probable hypothesis's objects, in key order
        let mut best: Vec<Key> = state
            .clusters
            .iter()
            .flat_map(|c| c.hypotheses[0].keys.iter().copied())
            .collect();
        best.sort_unstable();
        let mut result: Vec<(u64, Key)> = Vec::new();
        let mut at: KeyMap<u64, usize> = KeyMap::default();
        for key in best {
            let lineage = version(key).lineage;
            match at.get(&lineage) {
                Some(&i) => result[i].1 = key,
                None => {
                    at.insert(lineage, result.len());
                    result.push((lineage, key));
                }
            }
        }
        return result;
    }
    if state.time.is_none() {
        return Vec::new();
    }
    let floor = tables.min_existence;
    // sized once: at most one entry per stored version (no rehash as they fill)
    let versions = state.tracks.len();
    // each version's summary by its serial (one per stored version), the cache after
    let mut kept: Summaries = KeyMap::with_capacity_and_hasher(versions, Default::default());
    let mut totals = LineageTotals::new(floor, versions);
    // version `key` of probability mass `p`, added to its lineage's total
    let mut add = |key: Key, p: f64| {
        let entry = &state.tracks[&key];
        let lineage = entry.version.lineage;
        let inside = kept
            .entry(entry.serial)
            .or_insert_with(|| match cache.get(&entry.serial) {
                Some(made) => made.clone(),
                None => Arc::new(summary(&entry.version, tables)),
            })
            .inside;
        totals.add(lineage, key, p, entry.existence * inside);
    };
    for cluster in &state.clusters {
        if let [only] = cluster.hypotheses.as_slice() {
            // one hypothesis (a certain cluster): its keys, each once, have its mass
            let p = only.log_weight.exp();
            for &key in &only.keys {
                add(key, 0.0 + p);
            }
            continue;
        }
        // each version's probability mass, in order of first appearance
        let mut mass: Vec<(Key, f64)> = Vec::with_capacity(cluster.keys.len());
        let mut mass_at: KeyMap<Key, usize> = KeyMap::default();
        mass_at.reserve(cluster.keys.len());
        for h in &cluster.hypotheses {
            let p = h.log_weight.exp();
            for &key in &h.keys {
                match mass_at.get(&key) {
                    Some(&i) => mass[i].1 += p,
                    None => {
                        mass_at.insert(key, mass.len());
                        mass.push((key, 0.0 + p));
                    }
                }
            }
        }
        for (key, p) in mass {
            add(key, p);
        }
    }
    let marginals: Vec<Marginal> = totals
        .rows()
        .map(|(lineage, existence, key)| Marginal {
            lineage,
            existence,
            key,
        })
        .collect();
    *cache = kept;
    let best = best_keys(state);
    let points: Vec<(&[f64], &[f64])> = marginals
        .iter()
        .map(|m| {
            let summary = &cache[&state.tracks[&m.key].serial];
            (&summary.position[..], &summary.covariance[..])
        })
        .collect();
    let merged = same_objects(marginals, &points, state, tables, &best, shown, ids);
    merged
        .into_iter()
        .filter(|m| m.existence >= floor)
        .map(|m| (m.lineage, m.key))
        .collect()
}

/// The keys of the most probable hypothesis (`MHFState.best`: the best of every
/// cluster).
pub fn best_keys(state: &State) -> KeySet<Key> {
    let held = state
        .clusters
        .iter()
        .map(|c| c.hypotheses[0].keys.len())
        .sum();
    let mut best = KeySet::with_capacity_and_hasher(held, Default::default());
    best.extend(
        state
            .clusters
            .iter()
            .flat_map(|c| c.hypotheses[0].keys.iter().copied()),
    );
    best
}

/// One entry per physical object (`WorldModel._same_objects`): see the module docs.
/// `points[i]`: marginal `i`'s position `d` and its covariance `d x d`; `state`: the
/// state whose versions the marginals show; `best_keys`: the keys of the most probable
/// hypothesis of the model's latest state ([`best_keys`]).
fn same_objects(
    marginals: Vec<Marginal>,
    points: &[(&[f64], &[f64])],
    state: &State,
    tables: &Tables,
    best_keys: &KeySet<Key>,
    shown: &KeySet<u64>,
    ids: &KeyMap<u64, i64>,
) -> Vec<Marginal> {
    let d = tables.dim;
    let candidates: Vec<usize> = (0..marginals.len())
        .filter(|&i| marginals[i].existence >= GROUPING_FLOOR)
        .collect();
    if candidates.len() < 2 {
        return marginals;
    }
    let together: KeySet<u64> = candidates
        .iter()
        .filter(|&&i| best_keys.contains(&marginals[i].key))
        .map(|&i| marginals[i].lineage)
        .collect();
    if together.len() == candidates.len() {
        return marginals; // the most probable hypothesis holds each as shown
    }
    let count = candidates.len();
    let mut parent: Vec<usize> = (0..count).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let point = |i: usize| points[candidates[i]];
    let spread: Vec<f64> = (0..count)
        .map(|i| {
            let p = point(i).1;
            let mut total = 0.0;
            for a in 0..d {
                total += p[a * d + a];
            }
            total
        })
        .collect();
    let k = tables.class_count();
    let mut link = |a: usize, b: usize| {
        let ((position_a, covariance_a), (position_b, covariance_b)) = (point(a), point(b));
        let delta: Vec<f64> = (0..d).map(|i| position_a[i] - position_b[i]).collect();
        let mut squared = 0.0;
        for value in &delta {
            squared += value * value;
        }
        if squared > SAME_OBJECT_GATE * (spread[a] + spread[b]) {
            return;
        }
        if !coinciding(&delta, covariance_a, covariance_b, d) {
            return;
        }
        let (first, second) = (&marginals[candidates[a]], &marginals[candidates[b]]);
        if together.contains(&first.lineage) && together.contains(&second.lineage) {
            return; // the most probable hypothesis holds both: two objects
        }
        let (ca, cb) = (
            state.tracks[&first.key].version.cls,
            state.tracks[&second.key].version.cls,
        );
        if !tables.compatible[ca * k + cb] {
            return;
        }
        let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
        parent[ra] = rb;
    };
    let positions: Vec<&[f64]> = (0..count).map(|i| point(i).0).collect();
    match near_pairs(&positions, &spread) {
        Some(pairs) => pairs.into_iter().for_each(|(a, b)| link(a, b)),
        None => {
            for a in 0..count {
                for b in a + 1..count {
                    link(a, b);
                }
            }
        }
    }
    // groups in order of their first member
    let mut groups: Vec<Vec<usize>> = Vec::new();
    let mut group_of_root: KeyMap<u64, usize> = KeyMap::default();
    for i in 0..count {
        let r = root(&mut parent, i) as u64;
        match group_of_root.get(&r) {
            Some(&g) => groups[g].push(i),
            None => {
                group_of_root.insert(r, groups.len());
                groups.push(vec![i]);
            }
        }
    }
    let mut result: Vec<Option<Marginal>> = marginals.iter().cloned().map(Some).collect();
    let mut appended: Vec<Marginal> = Vec::new();
    for members in groups.iter().filter(|g| g.len() > 1) {
        let with_id: Vec<usize> = members
            .iter()
            .copied()
            .filter(|&i| shown.contains(&marginals[candidates[i]].lineage))
            .collect();
        let best = if !with_id.is_empty() {
            // min by (not together, id): the first of the smallest
            let mut best = with_id[0];
            let key = |i: usize| {
                let lineage = marginals[candidates[i]].lineage;
                (
                    !together.contains(&lineage),
                    ids.get(&lineage).copied().unwrap_or(0),
                )
            };
            for &i in &with_id[1..] {
                if key(i) < key(best) {
                    best = i;
                }
            }
            best
        } else {
            // the likeliest; existences within TIE of the largest are a tie, which the
            // oldest lineage (not rounding) decides
            let top = members
                .iter()
                .map(|&i| marginals[candidates[i]].existence)
                .fold(f64::NEG_INFINITY, f64::max);
            let mut best = members[0];
            let mut best_lineage = u64::MAX;
            for &i in members {
                let m = &marginals[candidates[i]];
                if m.existence >= top - TIE && m.lineage < best_lineage {
                    best = i;
                    best_lineage = m.lineage;
                }
            }
            best
        };
        let total = fsum(members.iter().map(|&i| marginals[candidates[i]].existence)).min(1.0);
        for &i in members {
            result[candidates[i]] = None;
        }
        appended.push(Marginal {
            existence: total,
            ..marginals[candidates[best]].clone()
        });
    }
    // deleted members leave their places; each group's entry goes to the end, in order
    let mut out: Vec<Marginal> = result.into_iter().flatten().collect();
    out.extend(appended);
    out
}

/// Up to this many candidates every pair is tested (`nearby.DENSE_PAIRS`: 64^2 pairs).
const DENSE_CANDIDATES: usize = 64;
/// The sweep's window widened against rounding: it may only admit more pairs to the
/// exact test, never fewer.
const WIDEN: f64 = 1.0 + 1e-9;

/// The pairs `(a, b)`, `a < b`, in the dense test's order, that may pass its cheap
/// bound `|x_a - x_b|^2 <= SAME_OBJECT_GATE (s_a + s_b)` (`s`: each covariance's trace):
/// a superset of the pairs that do, found by a sweep along the first axis, as the
/// specification finds them with a k-d tree (`nearby.close_pairs`). `None` (test every
/// pair) for a few candidates, and when a position or a spread is not finite (the dense
/// test's comparisons decide those).
fn near_pairs(positions: &[&[f64]], spread: &[f64]) -> Option<Vec<(usize, usize)>> {
    let count = positions.len();
    let finite = positions.iter().all(|p| p.iter().all(|v| v.is_finite()))
        && spread.iter().all(|s| s.is_finite());
    if count <= DENSE_CANDIDATES || !finite {
        return None;
    }
    let widest = spread.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mut order: Vec<usize> = (0..count).collect();
    order.sort_by(|&a, &b| positions[a][0].total_cmp(&positions[b][0]));
    let mut pairs = Vec::new();
    for (at, &i) in order.iter().enumerate() {
        // |x_a - x_b|^2 >= (x0_a - x0_b)^2, and s_a + s_b <= s_i + the widest spread
        let bound = SAME_OBJECT_GATE * (spread[i] + widest);
        let reach = if bound > 0.0 { bound * WIDEN } else { bound };
        for &j in &order[at + 1..] {
            let gap = positions[j][0] - positions[i][0];
            if gap * gap > reach {
                break;
            }
            pairs.push((i.min(j), i.max(j)));
        }
    }
    pairs.sort_unstable();
    Some(pairs)
}

/// The world of `state` predicted to `at` (`WorldModel._marginals` and
/// `_same_objects`): every version predicted to `at`, and one entry per physical
/// object, `(marginal, row)` with `row` the version's row of the prediction, in the
/// specification's order. `mht`: existence at `at`, objects leaving at their leave rates
/// past the state's time and nothing missed (a query is no scan); versions leaving at
/// `at` (`Filter::leaving`) count for nothing. `best_keys`, `shown` and `ids`: as
/// [`same_objects`] takes them, of the model's latest state. `paper`: every version
/// certain and inside, the objects of `state`'s most probable hypothesis only, none
/// grouped (`WorldModel.world`'s `paper` branch).
pub fn at(
    filter: &Filter,
    state: &State,
    at: f64,
    best_keys: &KeySet<Key>,
    shown: &KeySet<u64>,
    ids: &KeyMap<u64, i64>,
) -> KernelResult<(Predicted, Vec<(Marginal, usize)>)> {
    let tables = &filter.tables;
    let versions: Vec<Arc<Version>> = state.tracks.values().map(|e| e.version.clone()).collect();
    let predicted = predict(&versions, at, tables)?;
    let Some(time) = state.time else {
        return Ok((predicted, Vec::new()));
    };
    let (existence, inside) = if tables.mht {
        let inside = filter.inside(&predicted);
        // past the last scan no scan has missed anything: no missed-detection term
        let future = if at > time { at } else { time };
        let (existence, _) = filter.existence_at(state, &predicted, future, None, &inside);
        (existence, inside)
    } else {
        (vec![1.0; versions.len()], vec![1.0; versions.len()])
    };
    let gone = filter.leaving(&predicted, at, &existence, &inside);
    let row_of: KeyMap<Key, usize> = versions
        .iter()
        .enumerate()
        .map(|(i, v)| (v.key, i))
        .collect();
    let floor = tables.min_existence;
    // lineage -> (marginal, row), in order of first insertion (a Python dict)
    let mut result: Vec<(Marginal, usize)> = Vec::new();
    let mut result_at: KeyMap<u64, usize> = KeyMap::default();
    for cluster in &state.clusters {
        // the most probable hypothesis first: it shows each lineage where present
        let mut totals = LineageTotals::new(floor, cluster.keys.len());
        for h in &cluster.hypotheses {
            let p = h.log_weight.exp();
            for &key in &h.keys {
                let row = row_of[&key];
                if !gone[row] {
                    totals.add(versions[row].lineage, key, p, existence[row] * inside[row]);
                }
            }
        }
        for (lineage, total, key) in totals.rows() {
            let marginal = Marginal {
                lineage,
                existence: total.min(1.0),
                key,
            };
            match result_at.get(&lineage) {
                Some(&i) if result[i].0.existence < total => result[i] = (marginal, row_of[&key]),
                Some(_) => {}
                None => {
                    result_at.insert(lineage, result.len());
                    result.push((marginal, row_of[&key]));
                }
            }
        }
    }
    if !tables.mht {
        let best: KeySet<u64> = self::best_keys(state)
            .iter()
            .map(|key| state.tracks[key].version.lineage)
            .collect();
        result.retain(|(m, _)| best.contains(&m.lineage));
        return Ok((predicted, result));
    }
    let rows: KeyMap<u64, usize> = result.iter().map(|(m, row)| (m.lineage, *row)).collect();
    let points: Vec<(&[f64], &[f64])> = result
        .iter()
        .map(|(_, row)| (predicted.position(*row), predicted.covariance(*row)))
        .collect();
    let marginals = result.iter().map(|(m, _)| m.clone()).collect();
    let merged = same_objects(marginals, &points, state, tables, best_keys, shown, ids);
    let merged = merged
        .into_iter()
        .map(|m| {
            let row = rows[&m.lineage];
            (m, row)
        })
        .collect();
    Ok((predicted, merged))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic generator of test numbers in `[0, 1)` (no dependency).
    struct Numbers(u64);

    impl Numbers {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// The pairs `same_objects`' dense test lets past its cheap bound, in its order.
    fn passing(positions: &[Vec<f64>], spread: &[f64]) -> Vec<(usize, usize)> {
        let mut pairs = Vec::new();
        for a in 0..positions.len() {
            for b in a + 1..positions.len() {
                let squared: f64 = positions[a]
                    .iter()
                    .zip(&positions[b])
                    .map(|(p, q)| (p - q) * (p - q))
                    .fold(0.0, |total, value| total + value);
                if squared <= SAME_OBJECT_GATE * (spread[a] + spread[b]) {
                    pairs.push((a, b));
                }
            }
        }
        pairs
    }

    #[test]
    fn the_sweep_finds_every_pair_the_dense_bound_passes() {
        for (seed, d, scale) in [(1, 2, 10.0), (2, 3, 1.0), (3, 2, 0.5), (4, 2, 100.0)] {
            let mut numbers = Numbers(seed);
            let count = 300;
            // clusters one metre apart, some points sharing their first coordinate
            let positions: Vec<Vec<f64>> = (0..count)
                .map(|i| {
                    let cluster = (i % 20) as f64;
                    (0..d)
                        .map(|axis| {
                            if axis == 0 && i % 7 == 0 {
                                cluster
                            } else {
                                cluster + scale * numbers.next()
                            }
                        })
                        .collect()
                })
                .collect();
            let spread: Vec<f64> = (0..count)
                .map(|_| numbers.next() * numbers.next())
                .collect();
            let views: Vec<&[f64]> = positions.iter().map(|p| &p[..]).collect();
            let pairs = near_pairs(&views, &spread).expect("a sweep above the dense size");
            assert!(
                pairs.windows(2).all(|w| w[0] < w[1]),
                "in order, each pair once"
            );
            let found: KeySet<(usize, usize)> = pairs.iter().copied().collect();
            let needed = passing(&positions, &spread);
            assert!(!needed.is_empty(), "seed {seed}: no pair to find");
            for pair in &needed {
                assert!(found.contains(pair), "seed {seed}: {pair:?} missed");
            }
            assert!(
                pairs.len() < count * (count - 1) / 2,
                "seed {seed}: nothing pruned"
            );
        }
    }

    #[test]
    fn few_or_not_finite_candidates_are_tested_pair_by_pair() {
        let positions: Vec<Vec<f64>> = (0..100).map(|i| vec![i as f64, 0.0]).collect();
        let views: Vec<&[f64]> = positions.iter().map(|p| &p[..]).collect();
        let spread = vec![0.5; 100];
        assert!(near_pairs(&views[..DENSE_CANDIDATES], &spread[..DENSE_CANDIDATES]).is_none());
        assert!(near_pairs(&views, &spread).is_some());
        let mut spread_nan = spread.clone();
        spread_nan[3] = f64::NAN;
        assert!(near_pairs(&views, &spread_nan).is_none());
        let mut with_infinity = positions.clone();
        with_infinity[5][1] = f64::INFINITY;
        let views: Vec<&[f64]> = with_infinity.iter().map(|p| &p[..]).collect();
        assert!(near_pairs(&views, &spread).is_none());
    }
}
