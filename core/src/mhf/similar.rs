//! Merging hypotheses that hold the same objects with near-identical estimates:
//! `semwm/mhf/similar.py`, its specification; each function names the one it mirrors.
//!
//! Two hypotheses of a cluster often differ only in how one detection long ago was
//! explained: they hold the same objects (lineages), and their versions of each object
//! are the same estimate to within a fraction of its standard deviation. Two hypotheses
//! with the same lineages merge (their probabilities add, the more probable one's
//! versions are kept: a standard MHT hypothesis merge) when for every object whose
//! versions differ, `a` and `b`:
//!
//! ```text
//! (x_a - x_b)^T P_a^-1 (x_a - x_b) <= d2_max   per motion model,
//! |log det P_a - log det P_b| <= 0.1,
//! ```
//!
//! and their class, label, existence, model probabilities and class distribution agree
//! (existence, model and class probabilities within 0.01). `d2_max` is the world setting
//! `merge_distance` (0 turns merging off). The test is not symmetric: the distance is
//! measured with the covariance of `a`, the version the more probable hypothesis holds.
//!
//! The specification batches the pair tests with numpy (`slogdet` and `inv` from LAPACK's
//! LU with partial pivoting, `einsum`); here each pair is tested on its own, with the same
//! LU, so the numbers agree to rounding. Where numpy's `max` meets a NaN it returns NaN,
//! which fails every `<=`; "the largest is at most t" is therefore written here as "each
//! is at most t". The specification's `same_estimate` tests `max > t` instead, which a
//! NaN passes, and [`same_estimate`] keeps that difference ([`numpy_max`]).

use std::cell::OnceCell;
use std::cmp::Ordering;
use std::sync::Arc;

use crate::error::{KernelError, KernelResult};
use crate::filters::small::MAX_STATE;
use crate::mhf::hypotheses::{key_union, log_add, ties_in_order, Hypothesis, KeyMap, KeySet};
use crate::mhf::state::{FilterState, Key, Version};

/// Existence, model and class probabilities agree within this (`PROBABILITY_TOLERANCE`).
pub const PROBABILITY_TOLERANCE: f64 = 0.01;
/// `|log det P_a - log det P_b|` at most this (`LOG_DET_TOLERANCE`).
pub const LOG_DET_TOLERANCE: f64 = 0.1;
/// The cheap bound's margin against rounding (it must not cut a twin): `_WIDEN`.
const WIDEN: f64 = 1.0 + 1e-6;

// ------------------------------------------------------------------ one covariance's LU

/// The LU factorisation with partial pivoting of one `n x n` matrix (`n <= MAX_STATE`),
/// as LAPACK's `getrf` behind `numpy.linalg.slogdet`, `inv` and `solve`: the pivot is the
/// first entry of largest magnitude in its column, multipliers are scaled by the pivot's
/// reciprocal, and a pivot that is exactly zero makes the matrix singular.
struct Lu {
    n: usize,
    factors: [f64; MAX_STATE * MAX_STATE],
    /// `rows[i]`: the row of the matrix that the factors' row `i` came from.
    rows: [usize; MAX_STATE],
    /// Row interchanges made (their parity is the permutation's sign).
    swaps: usize,
}

impl Lu {
    /// The factorisation of `matrix` (row-major), `None` when it is singular (`getrf`'s
    /// `info > 0`, where `slogdet` gives sign 0 and `inv` and `solve` raise).
    fn of(matrix: &[f64], n: usize) -> Option<Lu> {
        let mut factors = [0.0; MAX_STATE * MAX_STATE];
        factors[..n * n].copy_from_slice(&matrix[..n * n]);
        let mut rows = [0usize; MAX_STATE];
        for (i, row) in rows.iter_mut().enumerate() {
            *row = i;
        }
        let mut swaps = 0;
        for k in 0..n {
            let mut best = k;
            for i in k + 1..n {
                if factors[i * n + k].abs() > factors[best * n + k].abs() {
                    best = i;
                }
            }
            let pivot = factors[best * n + k];
            if pivot == 0.0 {
                return None;
            }
            if best != k {
                for j in 0..n {
                    factors.swap(k * n + j, best * n + j);
                }
                rows.swap(k, best);
                swaps += 1;
            }
            let reciprocal = 1.0 / pivot;
            for i in k + 1..n {
                if pivot.abs() >= f64::MIN_POSITIVE {
                    factors[i * n + k] *= reciprocal;
                } else {
                    factors[i * n + k] /= pivot;
                }
                let multiplier = factors[i * n + k];
                for j in k + 1..n {
                    factors[i * n + j] -= multiplier * factors[k * n + j];
                }
            }
        }
        Some(Lu {
            n,
            factors,
            rows,
            swaps,
        })
    }

    /// `(sign, log |det|)` as `numpy.linalg.slogdet` computes them from the factors: the
    /// permutation's sign times each pivot's `u / |u|` (NaN for a NaN or infinite
    /// pivot), and the sum of `log |u|` in order.
    fn sign_and_log_det(&self) -> (f64, f64) {
        let n = self.n;
        let mut sign = if self.swaps % 2 == 1 { -1.0 } else { 1.0 };
        let mut log_det = 0.0;
        for i in 0..n {
            let pivot = self.factors[i * n + i];
            let size = pivot.abs();
            sign *= pivot / size;
            log_det += size.ln();
        }
        (sign, log_det)
    }

    /// Solves `A y = b` in place of `b` (`getrs`: the row interchanges, then the unit
    /// lower and the upper triangle).
    fn solve(&self, b: &mut [f64]) {
        let n = self.n;
        let mut y = [0.0; MAX_STATE];
        for i in 0..n {
            y[i] = b[self.rows[i]];
        }
        for i in 0..n {
            for k in 0..i {
                y[i] -= self.factors[i * n + k] * y[k];
            }
        }
        for i in (0..n).rev() {
            for k in i + 1..n {
                y[i] -= self.factors[i * n + k] * y[k];
            }
            y[i] /= self.factors[i * n + i];
        }
        b[..n].copy_from_slice(&y[..n]);
    }

    /// `A^-1` into `inverse` (`numpy.linalg.inv`: the solve of the identity's columns).
    fn inverse(&self, inverse: &mut [f64]) {
        let n = self.n;
        let mut column = [0.0; MAX_STATE];
        for j in 0..n {
            column[..n].fill(0.0);
            column[j] = 1.0;
            self.solve(&mut column[..n]);
            for i in 0..n {
                inverse[i * n + j] = column[i];
            }
        }
    }
}

/// `(sign, log |det|)` of each mode's covariance (`numpy.linalg.slogdet` of `P`):
/// `(0, -inf)` for a singular one.
fn slogdet(state: &FilterState) -> Vec<(f64, f64)> {
    let n = state.size;
    state
        .p
        .chunks_exact(n * n)
        .map(|matrix| match Lu::of(matrix, n) {
            Some(lu) => lu.sign_and_log_det(),
            None => (0.0, f64::NEG_INFINITY),
        })
        .collect()
}

/// `r^T A r` summed as `numpy.einsum("i,ij,j->", r, A, r)` sums: row by row, each row's
/// terms `(r_i A_ij) r_j` in order.
fn quadratic_form(residual: &[f64], matrix: &[f64], n: usize) -> f64 {
    let mut total = 0.0;
    for i in 0..n {
        let mut row = 0.0;
        for j in 0..n {
            row += residual[i] * matrix[i * n + j] * residual[j];
        }
        total += row;
    }
    total
}

/// `x_a - x_b` of one mode (the first `size` entries).
fn mode_delta(a: &FilterState, b: &FilterState, mode: usize) -> [f64; MAX_STATE] {
    let n = a.size;
    let mut delta = [0.0; MAX_STATE];
    let rows = a.x[mode * n..(mode + 1) * n]
        .iter()
        .zip(&b.x[mode * n..(mode + 1) * n]);
    for (entry, (xa, xb)) in delta.iter_mut().zip(rows) {
        *entry = xa - xb;
    }
    delta
}

/// `numpy.max` of `values`: NaN when any is NaN (numpy propagates it), else the largest;
/// `Value` error when there is none (numpy's "zero-size array to reduction operation
/// maximum which has no identity").
fn numpy_max(values: impl IntoIterator<Item = f64>) -> KernelResult<f64> {
    let mut largest: Option<f64> = None;
    for value in values {
        largest = Some(match largest {
            Some(so_far) if so_far.is_nan() || so_far >= value => so_far,
            _ => value,
        });
    }
    largest.ok_or_else(|| {
        KernelError::Value(
            "zero-size array to reduction operation maximum which has no identity".to_string(),
        )
    })
}

// ------------------------------------------------------------------------ one version pair

/// `Shape` error unless `version`'s filter state is consistent and of a size the kernels
/// take: `1..` modes of `1..=MAX_STATE` entries, `x` `(M, n)`, `P` `(M, n, n)`, `mu`
/// `(M,)`.
fn check_state(version: &Version) -> KernelResult<()> {
    let state = &version.state;
    let (m, n) = (state.modes, state.size);
    if m == 0 || n == 0 || n > MAX_STATE {
        return Err(KernelError::Shape(format!(
            "version {}: expected 1 or more modes of 1 to {MAX_STATE} state entries, got {m} \
             modes of {n}",
            version.key
        )));
    }
    for (name, got, expected) in [
        ("x", state.x.len(), m * n),
        ("P", state.p.len(), m * n * n),
        ("mu", state.mu.len(), m),
    ] {
        if got != expected {
            return Err(KernelError::Shape(format!(
                "version {}: {name}: expected {expected} values for {m} modes of {n}, got {got}",
                version.key
            )));
        }
    }
    Ok(())
}

/// `Shape` error unless two versions compared have class distributions of one length.
fn check_class_probs(a: &Version, b: &Version) -> KernelResult<()> {
    if a.class_probs.len() == b.class_probs.len() {
        Ok(())
    } else {
        Err(KernelError::Shape(format!(
            "versions {} and {}: class_probs of {} and {} classes",
            a.key,
            b.key,
            a.class_probs.len(),
            b.class_probs.len()
        )))
    }
}

/// Class, label and state shape `(modes, size)` agree: the versions `_same_pairs`
/// compares (with the lineage, which its caller groups by).
fn comparable(a: &Version, b: &Version) -> bool {
    a.cls == b.cls
        && a.label == b.label
        && (a.state.modes, a.state.size) == (b.state.modes, b.state.size)
}

/// `same_estimate`: whether two versions of one object are the same estimate (the
/// module's equations, the distance with `P_a`). Mirrors the Python function test by
/// test, including its `max > tolerance` tests that a NaN passes. Errors on a malformed
/// state, and on class distributions of different or zero length (numpy raises).
pub fn same_estimate(
    a: &Version,
    b: &Version,
    existence_a: f64,
    existence_b: f64,
    max_distance: f64,
) -> KernelResult<bool> {
    if a.key == b.key {
        return Ok(true);
    }
    check_state(a)?;
    check_state(b)?;
    if !comparable(a, b) {
        return Ok(false);
    }
    if (existence_a - existence_b).abs() > PROBABILITY_TOLERANCE {
        return Ok(false);
    }
    let (sa, sb) = (&a.state, &b.state);
    let mu_gap = numpy_max(sa.mu.iter().zip(&sb.mu).map(|(p, q)| (p - q).abs()))?;
    if mu_gap > PROBABILITY_TOLERANCE {
        return Ok(false);
    }
    check_class_probs(a, b)?;
    let class_gap = numpy_max(
        a.class_probs
            .iter()
            .zip(b.class_probs.iter())
            .map(|(p, q)| (p - q).abs()),
    )?;
    if class_gap > PROBABILITY_TOLERANCE {
        return Ok(false);
    }
    // d^2 per mode from `np.linalg.solve(P_a, delta)`, which raises (False) when any
    // mode's P_a is singular
    let (m, n) = (sa.modes, sa.size);
    let mut distances = Vec::with_capacity(m);
    for mode in 0..m {
        let Some(lu) = Lu::of(&sa.p[mode * n * n..(mode + 1) * n * n], n) else {
            return Ok(false);
        };
        let delta = mode_delta(sa, sb, mode);
        let mut solved = delta;
        lu.solve(&mut solved[..n]);
        let mut d2 = 0.0;
        for i in 0..n {
            d2 += delta[i] * solved[i];
        }
        distances.push(d2);
    }
    if numpy_max(distances)? > max_distance {
        return Ok(false);
    }
    let (dets_a, dets_b) = (slogdet(sa), slogdet(sb));
    if dets_a.iter().chain(&dets_b).any(|&(sign, _)| sign <= 0.0) {
        return Ok(false);
    }
    let log_det_gap = numpy_max(
        dets_a
            .iter()
            .zip(&dets_b)
            .map(|(&(_, la), &(_, lb))| (la - lb).abs()),
    )?;
    Ok(log_det_gap <= LOG_DET_TOLERANCE)
}

/// What the batched test reads of one version's covariances: whether every mode's
/// determinant is positive (`valid`), each mode's `log |P|`, and when valid each mode's
/// `P^-1` (`_same_in`'s `slogdet` and `inv`), made when a comparison first needs it.
struct Covariances {
    valid: bool,
    log_det: Vec<f64>,
    n: usize,
    factors: Vec<Option<Lu>>,
    inverse: OnceCell<Vec<f64>>,
}

impl Covariances {
    fn of(state: &FilterState) -> Covariances {
        let n = state.size;
        let factors: Vec<Option<Lu>> = state
            .p
            .chunks_exact(n * n)
            .map(|matrix| Lu::of(matrix, n))
            .collect();
        let dets: Vec<(f64, f64)> = factors
            .iter()
            .map(|lu| match lu {
                Some(lu) => lu.sign_and_log_det(),
                None => (0.0, f64::NEG_INFINITY),
            })
            .collect();
        Covariances {
            valid: dets.iter().all(|&(sign, _)| sign > 0.0),
            log_det: dets.into_iter().map(|(_, log_det)| log_det).collect(),
            n,
            factors,
            inverse: OnceCell::new(),
        }
    }

    /// Each mode's `P^-1`, `m x n x n` (only asked of a valid one: the specification
    /// inverts the identity in place of an invalid one, and masks the result).
    fn inverse(&self) -> &[f64] {
        self.inverse.get_or_init(|| {
            let nn = self.n * self.n;
            let mut inverse = vec![0.0; self.factors.len() * nn];
            for (lu, into) in self.factors.iter().zip(inverse.chunks_exact_mut(nn)) {
                if let Some(lu) = lu {
                    lu.inverse(into);
                }
            }
            inverse
        })
    }
}

/// `_same_in`'s cheap necessary condition: in the first mode, `|x_a - x_b|^2 <=
/// max_distance * trace(P_a) * (1 + 1e-6)` (`d2 <= max_distance` needs
/// `|x_a - x_b|^2 <= max_distance * lambda_max(P_a) <= max_distance * trace(P_a)`).
fn within_reach(a: &FilterState, b: &FilterState, max_distance: f64) -> bool {
    let n = a.size;
    let mut gap2 = 0.0;
    for i in 0..n {
        let gap = a.x[i] - b.x[i];
        gap2 += gap * gap;
    }
    let mut trace = 0.0;
    for i in 0..n {
        trace += a.p[i * n + i];
    }
    gap2 <= max_distance * trace * WIDEN
}

/// `_same_in`'s conditions on one ordered pair that passed [`within_reach`] that need no
/// covariance factor: existence, model and class probabilities agree. Errors as numpy
/// raises before it tests anything (class distributions of different or zero length).
fn probabilities_agree(
    (a, existence_a): (&Version, f64),
    (b, existence_b): (&Version, f64),
) -> KernelResult<bool> {
    check_class_probs(a, b)?;
    if a.class_probs.is_empty() {
        numpy_max(std::iter::empty())?;
    }
    let within = |p: f64, q: f64| (p - q).abs() <= PROBABILITY_TOLERANCE;
    Ok(within(existence_a, existence_b)
        && a.state
            .mu
            .iter()
            .zip(&b.state.mu)
            .all(|(&p, &q)| within(p, q))
        && a.class_probs
            .iter()
            .zip(b.class_probs.iter())
            .all(|(&p, &q)| within(p, q)))
}

/// `_same_in`'s remaining conditions on a pair that passed [`probabilities_agree`]: both
/// covariances' determinants positive and close, and the distance with `P_a` (the
/// specification's `&` of the same pure conditions; the one that needs an inverse last).
fn covariances_agree(
    (a, covariances_a): (&FilterState, &Covariances),
    (b, covariances_b): (&FilterState, &Covariances),
    max_distance: f64,
) -> bool {
    let (m, n) = (a.modes, a.size);
    let near = || {
        let inverses = covariances_a.inverse();
        (0..m).all(|mode| {
            let delta = mode_delta(a, b, mode);
            let inverse = &inverses[mode * n * n..(mode + 1) * n * n];
            quadratic_form(&delta[..n], inverse, n) <= max_distance
        })
    };
    covariances_a.valid
        && covariances_b.valid
        && covariances_a
            .log_det
            .iter()
            .zip(&covariances_b.log_det)
            .all(|(la, lb)| (la - lb).abs() <= LOG_DET_TOLERANCE)
        && near()
}

/// `_same_pairs`: the ordered key pairs `(a, b)`, `a != b`, of versions of one lineage
/// (`lineages`: the versions of each) that are the same estimate: only versions of one
/// class, label and state shape are compared, the cheap conditions first, and a
/// covariance is factored only for a pair that passes them. Every version in `lineages`
/// must have passed [`check_state`].
fn same_pairs(
    lineages: &[Vec<&Version>],
    existence: &KeyMap<Key, f64>,
    max_distance: f64,
) -> KernelResult<KeySet<(Key, Key)>> {
    let existence_of = |key: Key| existence.get(&key).copied().unwrap_or(1.0);
    let mut same = KeySet::default();
    for versions in lineages {
        let mut candidates: Vec<(usize, usize)> = Vec::new();
        for i in 0..versions.len() {
            for j in 0..versions.len() {
                let (a, b) = (versions[i], versions[j]);
                if i != j
                    && comparable(a, b)
                    && within_reach(&a.state, &b.state, max_distance)
                    && probabilities_agree((a, existence_of(a.key)), (b, existence_of(b.key)))?
                {
                    candidates.push((i, j));
                }
            }
        }
        if candidates.is_empty() {
            continue;
        }
        let mut covariances: Vec<Option<Covariances>> = versions.iter().map(|_| None).collect();
        for &(i, j) in &candidates {
            for k in [i, j] {
                if covariances[k].is_none() {
                    covariances[k] = Some(Covariances::of(&versions[k].state));
                }
            }
        }
        for (i, j) in candidates {
            let (a, b) = (versions[i], versions[j]);
            let (Some(covariances_a), Some(covariances_b)) = (&covariances[i], &covariances[j])
            else {
                continue; // both were made just above
            };
            if covariances_agree(
                (&a.state, covariances_a),
                (&b.state, covariances_b),
                max_distance,
            ) {
                same.insert((a.key, b.key));
            }
        }
    }
    Ok(same)
}

// ----------------------------------------------------------------------- the hypotheses

/// The version of `key`, or a `Value` error naming it.
fn version_of(versions: &KeyMap<Key, Arc<Version>>, key: Key) -> KernelResult<&Version> {
    versions
        .get(&key)
        .map(|version| &**version)
        .ok_or_else(|| KernelError::Value(format!("object version {key} is not given")))
}

/// Each member's keys ordered by lineage (the columns of `_twin_matrix`'s key matrix; the
/// members hold the same lineages). A hypothesis that holds two versions of one lineage
/// has no such row (the specification's matrix would be left partly unset): `Value`
/// error.
fn rows_by_lineage(
    members: &[usize],
    hypotheses: &[Hypothesis],
    versions: &KeyMap<Key, Arc<Version>>,
) -> KernelResult<Vec<Vec<Key>>> {
    members
        .iter()
        .map(|&index| {
            let mut held: Vec<(u64, Key)> = hypotheses[index]
                .keys
                .iter()
                .map(|&key| version_of(versions, key).map(|v| (v.lineage, key)))
                .collect::<KernelResult<_>>()?;
            held.sort_unstable();
            if let Some(pair) = held.windows(2).find(|pair| pair[0].0 == pair[1].0) {
                return Err(KernelError::Value(format!(
                    "hypothesis {index} holds two versions of lineage {} (keys {} and {})",
                    pair[0].0, pair[0].1, pair[1].1
                )));
            }
            Ok(held.into_iter().map(|(_, key)| key).collect())
        })
        .collect()
}

/// `_twin_matrix`'s `twins[a][b]` for two members of a group (rows of
/// [`rows_by_lineage`]): every version `b` holds is `a`'s version of that object, or the
/// same estimate as it (`(a's key, b's key)` in `same`).
fn is_twin(a: &[Key], b: &[Key], same: &KeySet<(Key, Key)>) -> bool {
    a.iter()
        .zip(b)
        .all(|(&key_a, &key_b)| key_a == key_b || same.contains(&(key_a, key_b)))
}

/// The groups of hypotheses holding the same objects (the same set of lineages):
/// each hypothesis's group, groups numbered in order of first appearance, and each
/// group's size. `keys`: every version the hypotheses hold, sorted. Each version's
/// lineage is read once; a hypothesis's set is a bit mask of the cluster's lineages
/// (a sorted list of them past 128).
fn lineage_groups(
    keys: &[Key],
    hypotheses: &[Hypothesis],
    versions: &KeyMap<Key, Arc<Version>>,
) -> KernelResult<(Vec<usize>, Vec<usize>)> {
    let mut index_of: KeyMap<u64, usize> = KeyMap::default();
    index_of.reserve(keys.len());
    let mut slots: Vec<usize> = Vec::with_capacity(keys.len());
    for &key in keys {
        let lineage = version_of(versions, key)?.lineage;
        let next = index_of.len();
        slots.push(*index_of.entry(lineage).or_insert(next));
    }
    let slot = |key: Key| -> KernelResult<usize> {
        keys.binary_search(&key)
            .map(|at| slots[at])
            .map_err(|_| KernelError::Value(format!("version {key} is not among the cluster's")))
    };
    let mut group_at: Vec<usize> = Vec::with_capacity(hypotheses.len());
    let mut sizes: Vec<usize> = Vec::new();
    let mut join = |group: usize, sizes: &mut Vec<usize>| {
        if group == sizes.len() {
            sizes.push(0);
        }
        sizes[group] += 1;
        group_at.push(group);
    };
    if index_of.len() <= 128 {
        let mut group_of: KeyMap<u128, usize> = KeyMap::default();
        group_of.reserve(hypotheses.len());
        for h in hypotheses {
            let mut held = 0u128;
            for &key in &h.keys {
                held |= 1u128 << slot(key)?;
            }
            let next = group_of.len();
            join(*group_of.entry(held).or_insert(next), &mut sizes);
        }
    } else {
        // each hypothesis's lineage slots, sorted and distinct, one after another
        let mut held: Vec<usize> = Vec::new();
        let mut spans: Vec<(usize, usize)> = Vec::with_capacity(hypotheses.len());
        for h in hypotheses {
            let start = held.len();
            for &key in &h.keys {
                held.push(slot(key)?);
            }
            held[start..].sort_unstable();
            let mut end = start;
            for at in start..held.len() {
                if end == start || held[at] != held[end - 1] {
                    held[end] = held[at];
                    end += 1;
                }
            }
            held.truncate(end);
            spans.push((start, end));
        }
        let mut group_of: KeyMap<&[usize], usize> = KeyMap::default();
        for &(start, end) in &spans {
            let next = group_of.len();
            join(
                *group_of.entry(&held[start..end]).or_insert(next),
                &mut sizes,
            );
        }
    }
    Ok((group_at, sizes))
}

/// `merge_similar`: the hypotheses (most probable first, normalised) with near-identical
/// twins merged into the more probable one; `None` when nothing merges (the caller keeps
/// its cluster as it is).
///
/// Hypotheses are grouped by the lineages they hold (groups in order of first
/// appearance); in each group, most probable first, a hypothesis joins the first kept
/// representative of which it is a twin (its probability added, `log_add`), else it is
/// kept. The kept hypotheses are returned sorted by descending weight, ties in their
/// order. `versions` holds every version the hypotheses hold; a key missing from
/// `existence` has existence 1.
pub fn merge_similar(
    hypotheses: &[Hypothesis],
    versions: &KeyMap<Key, Arc<Version>>,
    existence: &KeyMap<Key, f64>,
    max_distance: f64,
) -> KernelResult<Option<Vec<Hypothesis>>> {
    let keys = key_union(hypotheses.iter().map(|h| h.keys.as_slice()));
    merge_similar_in(&keys, hypotheses, versions, existence, max_distance)
}

/// [`merge_similar`] of a cluster's hypotheses, `keys` every version they hold, sorted
/// (`Cluster::keys`).
pub fn merge_similar_in(
    keys: &[Key],
    hypotheses: &[Hypothesis],
    versions: &KeyMap<Key, Arc<Version>>,
    existence: &KeyMap<Key, f64>,
    max_distance: f64,
) -> KernelResult<Option<Vec<Hypothesis>>> {
    if hypotheses.len() < 2 || max_distance <= 0.0 {
        return Ok(None);
    }
    let (group_at, sizes) = lineage_groups(keys, hypotheses, versions)?;
    if sizes.iter().all(|&size| size == 1) {
        return Ok(None); // no two hypotheses hold the same objects: the common scan
    }
    let mut groups: Vec<Vec<usize>> = sizes.iter().map(|&size| Vec::with_capacity(size)).collect();
    for (index, &group) in group_at.iter().enumerate() {
        groups[group].push(index);
    }
    // versions of each lineage held by hypotheses that have a twin candidate
    let mut lineage_at: KeyMap<u64, usize> = KeyMap::default();
    let mut by_lineage: Vec<Vec<&Version>> = Vec::new();
    let mut seen: KeySet<Key> = KeySet::default();
    for members in groups.iter().filter(|members| members.len() > 1) {
        for &index in members {
            for &key in &hypotheses[index].keys {
                if !seen.insert(key) {
                    continue;
                }
                let version = version_of(versions, key)?;
                let at = *lineage_at.entry(version.lineage).or_insert_with(|| {
                    by_lineage.push(Vec::new());
                    by_lineage.len() - 1
                });
                by_lineage[at].push(version);
            }
        }
    }
    by_lineage.retain(|lineage| lineage.len() > 1);
    for version in by_lineage.iter().flatten() {
        check_state(version)?;
    }
    let same = same_pairs(&by_lineage, existence, max_distance)?;
    if same.is_empty() {
        return Ok(None);
    }
    let mut weights: Vec<f64> = hypotheses.iter().map(|h| h.log_weight).collect();
    let mut absorbed = vec![false; hypotheses.len()];
    for members in groups.iter().filter(|members| members.len() > 1) {
        let rows = rows_by_lineage(members, hypotheses, versions)?;
        let mut kept: Vec<usize> = Vec::new(); // positions in members of the representatives
        for (position, &index) in members.iter().enumerate() {
            // most probable first
            let twin_of = kept
                .iter()
                .copied()
                .find(|&representative| is_twin(&rows[representative], &rows[position], &same));
            match twin_of {
                Some(representative) => {
                    let target = members[representative];
                    weights[target] = log_add(weights[target], weights[index]);
                    absorbed[index] = true;
                }
                None => kept.push(position),
            }
        }
    }
    if !absorbed.contains(&true) {
        return Ok(None);
    }
    let mut result: Vec<Hypothesis> = hypotheses
        .iter()
        .zip(&weights)
        .zip(&absorbed)
        .filter(|(_, &gone)| !gone)
        .map(|((h, &log_weight), _)| Hypothesis {
            log_weight,
            keys: h.keys.clone(),
            rate: h.rate,
        })
        .collect();
    // stable, descending: ties keep their order (Python's sort with reverse=True)
    result.sort_by(|a, b| {
        b.log_weight
            .partial_cmp(&a.log_weight)
            .unwrap_or(Ordering::Equal)
    });
    Ok(Some(ties_in_order(result)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A version of lineage `lineage` with one mode at `(x, 0)`, covariance `variance I`
    /// (2-D), class 0, no label, class distribution `[1, 0]` (the Python tests'
    /// `version`).
    fn version(key: Key, lineage: u64, x: f64, variance: f64) -> Version {
        version_with(
            key,
            lineage,
            &[x, 0.0],
            &[variance, 0.0, 0.0, variance],
            &[1.0],
        )
    }

    fn version_with(key: Key, lineage: u64, x: &[f64], p: &[f64], mu: &[f64]) -> Version {
        let modes = mu.len();
        Version {
            key,
            lineage,
            cls: 0,
            label: None,
            state: Arc::new(FilterState {
                modes,
                size: x.len() / modes,
                x: x.to_vec(),
                p: p.to_vec(),
                mu: mu.to_vec(),
            }),
            time: 1.0,
            last_seen: 1.0,
            created: 0.0,
            rate: 2.0,
            class_probs: Arc::from(vec![1.0, 0.0]),
            sources: Arc::from(Vec::new()),
        }
    }

    fn table(versions: Vec<Version>) -> KeyMap<Key, Arc<Version>> {
        versions.into_iter().map(|v| (v.key, Arc::new(v))).collect()
    }

    fn h(p: f64, keys: &[Key]) -> Hypothesis {
        Hypothesis {
            log_weight: p.ln(),
            keys: keys.to_vec(),
            rate: 2.0 * keys.len() as f64,
        }
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12
    }

    #[test]
    fn twins_merge_into_the_more_probable_and_probabilities_add() {
        // tests/mhf/test_similar.py's case
        let versions = table(vec![
            version(1, 7, 0.0, 0.01),
            version(2, 7, 0.005, 0.01), // a twin of 1
            version(3, 7, 0.5, 0.01),   // another estimate of the same object
            version(4, 8, 2.0, 0.01),
        ]);
        let hypotheses = [
            h(0.5, &[1, 4]),
            h(0.3, &[2, 4]),
            h(0.15, &[3, 4]),
            h(0.05, &[1]), // other objects: not a twin
        ];
        let merged = merge_similar(&hypotheses, &versions, &KeyMap::default(), 0.01)
            .unwrap()
            .unwrap();
        let keys: Vec<Vec<Key>> = merged.iter().map(|h| h.keys.clone()).collect();
        assert_eq!(keys, vec![vec![1, 4], vec![3, 4], vec![1]]);
        assert!(close(merged[0].log_weight, 0.8f64.ln()));
        assert!(close(merged[1].log_weight, 0.15f64.ln()));
        assert_eq!(merged[0].rate, 4.0);
        // 0 turns merging off
        let off = merge_similar(&hypotheses, &versions, &KeyMap::default(), 0.0).unwrap();
        assert!(off.is_none());
    }

    #[test]
    fn a_far_version_of_another_object_stops_the_merge() {
        // 2 and 1 are twins, but 6 is far from 5: the hypotheses are not twins
        let versions = table(vec![
            version(1, 7, 0.0, 0.01),
            version(2, 7, 0.005, 0.01),
            version(5, 8, 2.0, 0.01),
            version(6, 8, 2.5, 0.01),
        ]);
        let hypotheses = [h(0.6, &[1, 5]), h(0.4, &[2, 6])];
        let merged = merge_similar(&hypotheses, &versions, &KeyMap::default(), 0.01).unwrap();
        assert!(merged.is_none());
        // with 5 held by both, they merge
        let hypotheses = [h(0.6, &[1, 5]), h(0.4, &[2, 5])];
        let merged = merge_similar(&hypotheses, &versions, &KeyMap::default(), 0.01).unwrap();
        assert_eq!(merged.unwrap().len(), 1);
    }

    #[test]
    fn the_distance_is_measured_with_the_more_probable_versions_covariance() {
        // variances 0.0095 and 0.0085: 2 ln(0.0095 / 0.0085) = 0.22 apart in log det
        let a = version(1, 7, 0.0, 0.0095);
        let b = version(2, 7, 0.0095, 0.0085);
        // variances 0.0095 and 0.0091 (0.086 apart), 0.00965 apart: d^2 = 0.0098 with
        // P_1, 0.0102 with P_2
        let b_close = version(2, 7, 0.00965, 0.0091);
        assert!(!same_estimate(&a, &b, 1.0, 1.0, 0.01).unwrap()); // log det
        assert!(same_estimate(&a, &b_close, 1.0, 1.0, 0.01).unwrap());
        assert!(!same_estimate(&b_close, &a, 1.0, 1.0, 0.01).unwrap());
        let versions = table(vec![a, b_close]);
        // the hypothesis holding 1 is more probable: 2 is its twin
        let first = [h(0.6, &[1]), h(0.4, &[2])];
        let merged = merge_similar(&first, &versions, &KeyMap::default(), 0.01).unwrap();
        let merged = merged.unwrap();
        assert_eq!(merged.len(), 1);
        assert_eq!(merged[0].keys, vec![1]);
        assert!(close(merged[0].log_weight, 0.0));
        // the other way round, 1 is not a twin of 2
        let second = [h(0.6, &[2]), h(0.4, &[1])];
        let merged = merge_similar(&second, &versions, &KeyMap::default(), 0.01).unwrap();
        assert!(merged.is_none());
    }

    #[test]
    fn nothing_merges_is_none() {
        let versions = table(vec![version(1, 7, 0.0, 0.01), version(2, 7, 0.5, 0.01)]);
        let existence = KeyMap::default();
        let far = [h(0.6, &[1]), h(0.4, &[2])];
        assert!(merge_similar(&far, &versions, &existence, 0.01)
            .unwrap()
            .is_none());
        let one = [h(1.0, &[1])];
        assert!(merge_similar(&one, &versions, &existence, 0.01)
            .unwrap()
            .is_none());
        // different lineage sets: no candidates at all
        let versions = table(vec![version(1, 7, 0.0, 0.01), version(2, 8, 0.0, 0.01)]);
        let apart = [h(0.6, &[1]), h(0.4, &[2])];
        assert!(merge_similar(&apart, &versions, &existence, 0.01)
            .unwrap()
            .is_none());
    }

    #[test]
    fn a_class_label_existence_or_probability_difference_stops_it() {
        let a = version(1, 7, 0.0, 0.01);
        let mut other_class = version(2, 7, 0.0, 0.01);
        other_class.cls = 1;
        let mut other_label = version(3, 7, 0.0, 0.01);
        other_label.label = Some(Arc::from("peer1"));
        let mut other_classes = version(4, 7, 0.0, 0.01);
        other_classes.class_probs = Arc::from(vec![0.9, 0.1]);
        let twin = version(5, 7, 0.0, 0.01);
        for b in [&other_class, &other_label, &other_classes] {
            assert!(!same_estimate(&a, b, 1.0, 1.0, 0.01).unwrap());
        }
        assert!(same_estimate(&a, &twin, 1.0, 1.0, 0.01).unwrap());
        assert!(!same_estimate(&a, &twin, 1.0, 0.9, 0.01).unwrap()); // existence
        let versions = table(vec![a, other_class, other_label, other_classes, twin]);
        for other in [2, 3, 4] {
            let pair = [h(0.6, &[1]), h(0.4, &[other])];
            let merged = merge_similar(&pair, &versions, &KeyMap::default(), 0.01).unwrap();
            assert!(merged.is_none(), "version {other} merged");
        }
        let pair = [h(0.6, &[1]), h(0.4, &[5])];
        let existence: KeyMap<Key, f64> = [(5, 0.9)].into_iter().collect();
        assert!(merge_similar(&pair, &versions, &existence, 0.01)
            .unwrap()
            .is_none());
        let existence: KeyMap<Key, f64> = [(5, 0.995)].into_iter().collect();
        assert!(merge_similar(&pair, &versions, &existence, 0.01)
            .unwrap()
            .is_some());
    }

    #[test]
    fn a_covariance_with_a_determinant_not_positive_never_merges() {
        // singular (sign 0) and negative determinant: invalid however close
        let a = version(1, 7, 0.0, 0.01);
        let singular = version_with(2, 7, &[0.0, 0.0], &[0.01, 0.0, 0.0, 0.0], &[1.0]);
        let negative = version_with(3, 7, &[0.0, 0.0], &[0.01, 0.0, 0.0, -0.01], &[1.0]);
        // two negative eigenvalues: a positive determinant, which the test accepts
        let both = version_with(4, 7, &[0.0, 0.0], &[-0.01, 0.0, 0.0, -0.01], &[1.0]);
        let versions = table(vec![a, singular, negative, both]);
        for other in [2, 3] {
            let pair = [h(0.6, &[1]), h(0.4, &[other])];
            let merged = merge_similar(&pair, &versions, &KeyMap::default(), 0.01).unwrap();
            assert!(merged.is_none(), "version {other} merged");
        }
        let pair = [h(0.6, &[4]), h(0.4, &[1])];
        // the cheap bound: trace(P_4) < 0 reaches nothing
        assert!(merge_similar(&pair, &versions, &KeyMap::default(), 0.01)
            .unwrap()
            .is_none());
        let pair = [h(0.6, &[1]), h(0.4, &[4])];
        assert!(merge_similar(&pair, &versions, &KeyMap::default(), 0.01)
            .unwrap()
            .is_some());
    }

    #[test]
    fn hypotheses_merge_only_in_their_group_and_ties_keep_their_order() {
        // groups {7} and {7, 8}; the first of each keeps the weight of its twin
        let versions = table(vec![
            version(1, 7, 0.0, 0.01),
            version(2, 7, 0.001, 0.01),
            version(3, 8, 5.0, 0.01),
        ]);
        let hypotheses = [h(0.3, &[1]), h(0.3, &[1, 3]), h(0.2, &[2, 3]), h(0.2, &[2])];
        let merged = merge_similar(&hypotheses, &versions, &KeyMap::default(), 0.1)
            .unwrap()
            .unwrap();
        let keys: Vec<Vec<Key>> = merged.iter().map(|h| h.keys.clone()).collect();
        assert_eq!(keys, vec![vec![1], vec![1, 3]]); // equal weights: in their order
        assert!(close(merged[0].log_weight, 0.5f64.ln()));
        assert!(close(merged[1].log_weight, 0.5f64.ln()));
    }

    #[test]
    fn two_modes_each_within_the_distance() {
        // the second mode is far: no merge; the same mode near: merge
        let p = [0.01, 0.0, 0.0, 0.01, 0.01, 0.0, 0.0, 0.01];
        let a = version_with(1, 7, &[0.0, 0.0, 0.0, 0.0], &p, &[0.5, 0.5]);
        let far = version_with(2, 7, &[0.0, 0.0, 0.5, 0.0], &p, &[0.5, 0.5]);
        let near = version_with(3, 7, &[0.0, 0.0, 0.001, 0.0], &p, &[0.505, 0.495]);
        assert!(!same_estimate(&a, &far, 1.0, 1.0, 0.01).unwrap());
        assert!(same_estimate(&a, &near, 1.0, 1.0, 0.01).unwrap());
        let versions = table(vec![a, far, near]);
        let hypotheses = [h(0.5, &[1]), h(0.3, &[2]), h(0.2, &[3])];
        let merged = merge_similar(&hypotheses, &versions, &KeyMap::default(), 0.01)
            .unwrap()
            .unwrap();
        let keys: Vec<Vec<Key>> = merged.iter().map(|h| h.keys.clone()).collect();
        assert_eq!(keys, vec![vec![1], vec![2]]);
        assert!(close(merged[0].log_weight, 0.7f64.ln()));
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let versions = table(vec![version(1, 7, 0.0, 0.01), version(2, 7, 0.0, 0.01)]);
        let missing = [h(0.6, &[1]), h(0.4, &[9])];
        assert!(matches!(
            merge_similar(&missing, &versions, &KeyMap::default(), 0.01),
            Err(KernelError::Value(_))
        ));
        let mut broken = version(3, 7, 0.0, 0.01);
        broken.state = Arc::new(FilterState {
            modes: 1,
            size: 2,
            x: vec![0.0, 0.0],
            p: vec![0.01],
            mu: vec![1.0],
        });
        let versions = table(vec![version(1, 7, 0.0, 0.01), broken]);
        let pair = [h(0.6, &[1]), h(0.4, &[3])];
        assert!(matches!(
            merge_similar(&pair, &versions, &KeyMap::default(), 0.01),
            Err(KernelError::Shape(_))
        ));
        // two versions of one lineage in one hypothesis
        let versions = table(vec![
            version(1, 7, 0.0, 0.01),
            version(2, 7, 0.0, 0.01),
            version(3, 8, 0.0, 0.01),
        ]);
        let doubled = [h(0.6, &[1, 2, 3]), h(0.4, &[2, 3])];
        assert!(matches!(
            merge_similar(&doubled, &versions, &KeyMap::default(), 0.01),
            Err(KernelError::Value(_))
        ));
    }

    #[test]
    fn the_lu_gives_numpys_sign_and_log_det_and_inverse() {
        // rows swapped: det of [[1, 2], [3, 4]] is -2
        let lu = Lu::of(&[1.0, 2.0, 3.0, 4.0], 2).unwrap();
        let (sign, log_det) = lu.sign_and_log_det();
        assert_eq!(sign, -1.0);
        assert!(close(log_det, 2f64.ln()));
        let s = [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0];
        let lu = Lu::of(&s, 3).unwrap();
        let mut inverse = [0.0; 9];
        lu.inverse(&mut inverse);
        for i in 0..3 {
            for j in 0..3 {
                let product: f64 = (0..3).map(|k| s[i * 3 + k] * inverse[k * 3 + j]).sum();
                assert!(close(product, if i == j { 1.0 } else { 0.0 }));
            }
        }
        assert!(Lu::of(&[1.0, 2.0, 2.0, 4.0], 2).is_none());
        assert!(numpy_max([1.0, f64::NAN, 3.0]).unwrap().is_nan());
        assert_eq!(numpy_max([1.0, 3.0, 2.0]).unwrap(), 3.0);
        assert!(numpy_max(std::iter::empty()).is_err());
    }
}
