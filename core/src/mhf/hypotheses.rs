//! Hypotheses, merging, pruning and normalising (paper 002 III-D, eq. (3); paper 000 C1):
//! the kernels of `semwm/mhf/prune.py`, which is their specification.
//!
//! A hypothesis is a set of object versions (their keys, kept as a sorted `Vec<u64>`),
//! a log weight and `rate`, the sum of f_existing over its objects (paper 002 eqs.
//! (5)-(7)). Children that hold the same objects merge: their probabilities add
//! (log-sum-exp, in the order the children were made), and the first child's rate is
//! kept (`merge`). `prune` keeps the hypotheses within `ratio` of the best (eq. 3) and
//! at most n_hyp,max of them, and normalises:
//!
//! ```text
//! p(h^i_k | z_1:k) >= alpha max_j p(h^j_k | z_1:k)
//! ```
//!
//! Orders are the specification's: merged entries in the order their key sets first
//! appeared, sorted by weight with ties kept in that order (Python's stable sort), and
//! the normaliser summed exactly as `math.fsum` sums, so that both engines give the
//! same hypotheses in the same order.

use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

use crate::error::{KernelError, KernelResult};

/// A small, fast hasher for keys of object versions (the multiply-rotate hash of
/// rustc's `FxHasher`): the maps here hold a scan's few dozen keys, where SipHash's
/// protection against crafted keys costs more than the lookups themselves.
#[derive(Default, Clone, Copy)]
pub struct KeyHasher(u64);

const SEED: u64 = 0x51_7c_c1_b7_27_22_0a_95;

impl Hasher for KeyHasher {
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(word));
        }
    }

    fn write_u64(&mut self, value: u64) {
        self.0 = (self.0.rotate_left(5) ^ value).wrapping_mul(SEED);
    }

    fn write_usize(&mut self, value: usize) {
        self.write_u64(value as u64);
    }

    fn write_u32(&mut self, value: u32) {
        self.write_u64(u64::from(value));
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

/// A `HashMap` with [`KeyHasher`].
pub type KeyMap<K, V> = HashMap<K, V, BuildHasherDefault<KeyHasher>>;
/// A `HashSet` with [`KeyHasher`].
pub type KeySet<K> = HashSet<K, BuildHasherDefault<KeyHasher>>;

/// The hash of a sorted key set (the merge's index).
fn hash_keys(keys: &[u64]) -> u64 {
    let mut hasher = KeyHasher::default();
    for &key in keys {
        hasher.write_u64(key);
    }
    hasher.write_usize(keys.len());
    hasher.finish()
}

/// One hypothesis: its objects (sorted keys), log weight and total rate (Hz).
#[derive(Debug, Clone, PartialEq)]
pub struct Hypothesis {
    pub log_weight: f64,
    pub keys: Vec<u64>,
    pub rate: f64,
}

/// Hypotheses over a group of objects (`semwm.mhf.state.Cluster`): `keys` is every
/// object version its hypotheses hold, sorted.
#[derive(Debug, Clone, PartialEq)]
pub struct Cluster {
    pub hypotheses: Vec<Hypothesis>,
    pub keys: Vec<u64>,
}

/// The union of key sets, sorted, each key once.
pub fn key_union<'a>(sets: impl IntoIterator<Item = &'a [u64]>) -> Vec<u64> {
    let mut keys: Vec<u64> = sets.into_iter().flatten().copied().collect();
    keys.sort_unstable();
    keys.dedup();
    keys
}

impl Cluster {
    /// The cluster of `hypotheses`, its keys their union (`Cluster.of`).
    pub fn of(hypotheses: Vec<Hypothesis>) -> Cluster {
        let keys = key_union(hypotheses.iter().map(|h| h.keys.as_slice()));
        Cluster { hypotheses, keys }
    }

    /// A cluster holding `key` for certain: one hypothesis, probability 1 (`_certain`).
    pub fn certain(key: u64, rate: f64) -> Cluster {
        Cluster {
            hypotheses: vec![Hypothesis {
                log_weight: 0.0,
                keys: vec![key],
                rate,
            }],
            keys: vec![key],
        }
    }
}

/// Log weights closer than this are a tie (`semwm.mhf.prune.TIE`): the rounding of the
/// arithmetic that made them never decides (eq. 3's floor keeps what lies within it of
/// the floor; tied hypotheses are ordered by the objects they hold).
pub const TIE: f64 = 1e-9;

/// `ties_in_order`: hypotheses (most probable first) with each run of ties (log weights
/// within `TIE` of the run's first) ordered by their sorted keys.
pub fn ties_in_order(items: Vec<Hypothesis>) -> Vec<Hypothesis> {
    let count = items.len();
    let mut runs: Vec<(usize, usize)> = Vec::new();
    let mut i = 0;
    while i < count {
        let mut j = i + 1;
        while j < count && items[i].log_weight - items[j].log_weight <= TIE {
            j += 1;
        }
        if j - i > 1 {
            runs.push((i, j));
        }
        i = j;
    }
    if runs.is_empty() {
        return items;
    }
    let mut items = items;
    for (start, end) in runs {
        // stable, as Python's sorted
        items[start..end].sort_by(|a, b| a.keys.cmp(&b.keys));
    }
    items
}

/// `log(exp(a) + exp(b))` without overflow (`log_add`).
pub fn log_add(a: f64, b: f64) -> f64 {
    let (a, b) = if a < b { (b, a) } else { (a, b) };
    if b == f64::NEG_INFINITY {
        return a;
    }
    a + (b - a).exp().ln_1p()
}

/// `math.log`: the natural logarithm, `ValueError("math domain error")` for `x <= 0`
/// (and NaN for NaN), as Python raises.
pub fn checked_ln(x: f64) -> KernelResult<f64> {
    if x > 0.0 || x.is_nan() {
        Ok(x.ln())
    } else {
        Err(KernelError::Value("math domain error".to_string()))
    }
}

/// The correctly rounded sum of `values`, as CPython's `math.fsum` computes it
/// (Shewchuk's exact partials, then the half-way correction of the last rounding).
pub fn fsum(values: impl IntoIterator<Item = f64>) -> f64 {
    let mut partials: Vec<f64> = Vec::new();
    let mut special = 0.0_f64;
    let mut infinite = 0.0_f64;
    for value in values {
        let mut x = value;
        let mut kept = 0;
        for j in 0..partials.len() {
            let mut y = partials[j];
            if x.abs() < y.abs() {
                std::mem::swap(&mut x, &mut y);
            }
            let hi = x + y;
            let lo = y - (hi - x);
            if lo != 0.0 {
                partials[kept] = lo;
                kept += 1;
            }
            x = hi;
        }
        partials.truncate(kept);
        if x != 0.0 {
            if !x.is_finite() {
                // an infinite or NaN input (an overflow of finite ones: +-inf as well)
                if value.is_infinite() {
                    infinite += value;
                }
                special += value;
                partials.clear();
            } else {
                partials.push(x);
            }
        }
    }
    if special != 0.0 {
        return if infinite.is_nan() { f64::NAN } else { special };
    }
    let mut n = partials.len();
    let mut hi = 0.0;
    if n > 0 {
        n -= 1;
        hi = partials[n];
        let mut lo = 0.0;
        while n > 0 {
            let x = hi;
            n -= 1;
            let y = partials[n];
            hi = x + y;
            lo = y - (hi - x);
            if lo != 0.0 {
                break;
            }
        }
        if n > 0 && ((lo < 0.0 && partials[n - 1] < 0.0) || (lo > 0.0 && partials[n - 1] > 0.0)) {
            let y = lo * 2.0;
            let x = hi + y;
            if y == x - hi {
                hi = x;
            }
        }
    }
    hi
}

/// Children being merged (`merge`): one entry per distinct set of objects, in the order
/// the sets first appeared. The index maps a key set's hash to its first entry; entries
/// whose sets share a hash are chained (`next`), so no key set is stored twice.
#[derive(Debug, Default)]
pub struct Merged {
    index: KeyMap<u64, usize>,
    next: Vec<usize>,
    entries: Vec<Hypothesis>,
}

const END: usize = usize::MAX;

impl Merged {
    pub fn new() -> Merged {
        Merged::default()
    }

    /// Room for `children` distinct entries without growing.
    pub fn with_capacity(children: usize) -> Merged {
        let mut index = KeyMap::default();
        index.reserve(children);
        Merged {
            index,
            next: Vec::with_capacity(children),
            entries: Vec::with_capacity(children),
        }
    }

    /// Adds a child: a new entry for a new set of objects, else its probability added
    /// to the entry's (the entry keeps its first rate).
    pub fn add(&mut self, keys: Vec<u64>, log_weight: f64, rate: f64) {
        let hash = hash_keys(&keys);
        let new = self.entries.len();
        let mut at = match self.index.get(&hash) {
            Some(&first) => first,
            None => {
                self.index.insert(hash, new);
                END
            }
        };
        let mut last = END;
        while at != END {
            let entry = &mut self.entries[at];
            if entry.keys == keys {
                entry.log_weight = log_add(entry.log_weight, log_weight);
                return;
            }
            last = at;
            at = self.next[at];
        }
        if last != END {
            self.next[last] = new;
        }
        self.next.push(END);
        self.entries.push(Hypothesis {
            log_weight,
            keys,
            rate,
        });
    }

    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

/// `merge`: children that hold the same objects merged.
pub fn merge(children: impl IntoIterator<Item = Hypothesis>) -> Merged {
    let children = children.into_iter();
    let mut merged = Merged::with_capacity(children.size_hint().0);
    for child in children {
        merged.add(child.keys, child.log_weight, child.rate);
    }
    merged
}

/// `prune`: the hypotheses within `ratio` of the best (eq. 3), at most
/// `max_hypotheses`, normalised, most probable first. `ValueError` when every
/// hypothesis has zero probability.
pub fn prune(merged: Merged, ratio: f64, max_hypotheses: usize) -> KernelResult<Vec<Hypothesis>> {
    // `lw > -inf` also drops NaN, as the specification's comparison does
    let mut items: Vec<Hypothesis> = merged
        .entries
        .into_iter()
        .filter(|h| h.log_weight > f64::NEG_INFINITY)
        .collect();
    if items.is_empty() {
        return Err(KernelError::Value(
            "every hypothesis has zero probability".to_string(),
        ));
    }
    // stable, descending: ties keep their order (Python's sort with reverse=True)
    items.sort_by(|a, b| {
        b.log_weight
            .partial_cmp(&a.log_weight)
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let best = items[0].log_weight;
    if ratio > 0.0 {
        let floor = best + ratio.ln() - TIE;
        items.retain(|h| h.log_weight >= floor);
    }
    let mut items = ties_in_order(items);
    items.truncate(max_hypotheses);
    let log_total = best + fsum(items.iter().map(|h| (h.log_weight - best).exp())).ln();
    for h in &mut items {
        h.log_weight -= log_total;
    }
    Ok(items)
}

/// Sorted `keys` with `key` added.
pub fn with_key(keys: &[u64], key: u64) -> Vec<u64> {
    let mut result = Vec::with_capacity(keys.len() + 1);
    match keys.binary_search(&key) {
        Ok(_) => result.extend_from_slice(keys),
        Err(at) => {
            result.extend_from_slice(&keys[..at]);
            result.push(key);
            result.extend_from_slice(&keys[at..]);
        }
    }
    result
}

/// Sorted `keys` with `old` replaced by `new` (`(keys - {old}) | {new}`).
pub fn replaced(keys: &[u64], old: u64, new: u64) -> Vec<u64> {
    let mut result = Vec::with_capacity(keys.len() + 1);
    let mut placed = false;
    for &key in keys {
        if key == old {
            continue;
        }
        if !placed && new <= key {
            placed = true;
            if new < key {
                result.push(new);
            }
        }
        result.push(key);
    }
    if !placed {
        result.push(new);
    }
    result
}

/// Whether sorted `keys` holds `key`.
pub fn holds(keys: &[u64], key: u64) -> bool {
    keys.binary_search(&key).is_ok()
}

/// The union of two sorted key sets.
pub fn union(a: &[u64], b: &[u64]) -> Vec<u64> {
    let mut result = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        match a[i].cmp(&b[j]) {
            std::cmp::Ordering::Less => {
                result.push(a[i]);
                i += 1;
            }
            std::cmp::Ordering::Greater => {
                result.push(b[j]);
                j += 1;
            }
            std::cmp::Ordering::Equal => {
                result.push(a[i]);
                i += 1;
                j += 1;
            }
        }
    }
    result.extend_from_slice(&a[i..]);
    result.extend_from_slice(&b[j..]);
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    fn h(log_weight: f64, keys: &[u64], rate: f64) -> Hypothesis {
        Hypothesis {
            log_weight,
            keys: keys.to_vec(),
            rate,
        }
    }

    #[test]
    fn log_add_is_log_sum_exp() {
        let (a, b) = (-1.25_f64, -3.5_f64);
        assert!((log_add(a, b) - (a.exp() + b.exp()).ln()).abs() < 1e-15);
        assert_eq!(log_add(a, f64::NEG_INFINITY), a);
        assert_eq!(log_add(f64::NEG_INFINITY, a), a);
        assert_eq!(log_add(1000.0, 1000.0), 1000.0 + 2.0_f64.ln());
    }

    #[test]
    fn fsum_is_exact() {
        assert_eq!(fsum([0.1; 10]), 1.0);
        assert_eq!(fsum([1e100, 1.0, -1e100]), 1.0);
        assert_eq!(fsum([1.0, 1e-16, 1e-16]), 1.0000000000000002);
        assert_eq!(fsum(Vec::new()), 0.0);
        assert!(fsum([f64::INFINITY, 1.0]).is_infinite());
    }

    #[test]
    fn merge_adds_the_probabilities_of_equal_sets_and_keeps_the_first_rate() {
        let merged = merge(vec![
            h(-1.0, &[1, 2], 3.0),
            h(-2.0, &[3], 1.0),
            h(-1.5, &[1, 2], 9.0),
        ]);
        assert_eq!(merged.len(), 2);
        assert_eq!(merged.entries[0].keys, vec![1, 2]);
        assert_eq!(merged.entries[0].rate, 3.0);
        assert!((merged.entries[0].log_weight - log_add(-1.0, -1.5)).abs() < 1e-15);
        assert_eq!(merged.entries[1].keys, vec![3]);
    }

    #[test]
    fn prune_normalises_most_probable_first() {
        let pruned = prune(
            merge(vec![
                h(-3.0, &[1], 1.0),
                h(-1.0, &[2], 1.0),
                h(-2.0, &[3], 1.0),
            ]),
            0.0,
            10,
        )
        .unwrap();
        let keys: Vec<u64> = pruned.iter().map(|h| h.keys[0]).collect();
        assert_eq!(keys, vec![2, 3, 1]);
        let total: f64 = pruned.iter().map(|h| h.log_weight.exp()).sum();
        assert!((total - 1.0).abs() < 1e-15);
        assert!((pruned[0].log_weight - pruned[1].log_weight - 1.0).abs() < 1e-15);
    }

    #[test]
    fn prune_applies_the_ratio_and_the_count_and_keeps_the_best() {
        let children = || {
            vec![
                h(-0.1, &[1], 0.0),
                h(-5.0, &[2], 0.0),
                h(-0.2, &[3], 0.0),
                h(-0.3, &[4], 0.0),
            ]
        };
        // eq. (3): alpha = 0.01 drops the child e^-4.9 times the best
        let by_ratio = prune(merge(children()), 0.01, 10).unwrap();
        assert_eq!(by_ratio.len(), 3);
        // n_hyp,max = 2: the two best, renormalised
        let by_count = prune(merge(children()), 0.0, 2).unwrap();
        let keys: Vec<u64> = by_count.iter().map(|h| h.keys[0]).collect();
        assert_eq!(keys, vec![1, 3]);
        let total: f64 = by_count.iter().map(|h| h.log_weight.exp()).sum();
        assert!((total - 1.0).abs() < 1e-15);
    }

    #[test]
    fn prune_orders_ties_by_their_objects_and_drops_zero_probability() {
        let pruned = prune(
            merge(vec![
                h(-1.0, &[5], 0.0),
                h(f64::NEG_INFINITY, &[6], 0.0),
                h(-1.0 - 1e-13, &[4], 0.0), // a tie, rounded apart
                h(f64::NAN, &[7], 0.0),
            ]),
            0.0,
            10,
        )
        .unwrap();
        let keys: Vec<u64> = pruned.iter().map(|h| h.keys[0]).collect();
        assert_eq!(keys, vec![4, 5]);
    }

    #[test]
    fn rounding_never_decides_the_floor_or_the_cap() {
        // exactly alpha of the best in exact arithmetic, a last bit below after rounding
        let alpha: f64 = 0.01;
        let at_floor = alpha.ln() - 1e-14;
        let kept = prune(
            merge(vec![h(0.0, &[1], 0.0), h(at_floor, &[2], 0.0)]),
            alpha,
            10,
        );
        assert_eq!(kept.unwrap().len(), 2);
        // three ties for two places: the two that hold the smallest keys, whatever the bits
        let capped = prune(
            merge(vec![
                h(0.0, &[1], 0.0),
                h(-1.0 + 1e-14, &[9], 0.0),
                h(-1.0, &[3], 0.0),
                h(-1.0 - 1e-14, &[2], 0.0),
            ]),
            0.0,
            3,
        )
        .unwrap();
        let keys: Vec<u64> = capped.iter().map(|h| h.keys[0]).collect();
        assert_eq!(keys, vec![1, 2, 3]);
    }

    #[test]
    fn prune_of_nothing_probable_is_an_error() {
        let error = prune(merge(vec![h(f64::NEG_INFINITY, &[1], 0.0)]), 0.0, 10).unwrap_err();
        assert_eq!(
            error,
            KernelError::Value("every hypothesis has zero probability".to_string())
        );
        assert!(prune(Merged::new(), 0.5, 10).is_err());
    }

    #[test]
    fn key_sets_stay_sorted() {
        assert_eq!(with_key(&[1, 5, 9], 6), vec![1, 5, 6, 9]);
        assert_eq!(with_key(&[1, 5], 5), vec![1, 5]);
        assert_eq!(replaced(&[1, 5, 9], 5, 12), vec![1, 9, 12]);
        assert_eq!(replaced(&[1, 5, 9], 5, 3), vec![1, 3, 9]);
        assert_eq!(replaced(&[1, 5, 9], 1, 9), vec![5, 9]);
        assert_eq!(replaced(&[1, 5, 9], 9, 0), vec![0, 1, 5]);
        assert_eq!(replaced(&[], 9, 4), vec![4]);
        assert_eq!(union(&[1, 4, 8], &[2, 4, 9]), vec![1, 2, 4, 8, 9]);
        assert!(holds(&[1, 4, 8], 4) && !holds(&[1, 4, 8], 5));
        let cluster = Cluster::of(vec![h(0.0, &[3, 1], 0.0), h(0.0, &[2, 3], 0.0)]);
        assert_eq!(cluster.keys, vec![1, 2, 3]);
    }
}
