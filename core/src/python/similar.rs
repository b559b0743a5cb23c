//! `semwm._core.merge_similar`: `crate::mhf::similar::merge_similar` on hypotheses and
//! versions given as plain lists, for the parity test (tests/engines/test_similar.py)
//! only; the engine calls the Rust function directly.
//!
//! The hypotheses: `hypothesis_keys` (a list of keys each), `log_weights`, `rates`.
//! The versions, one entry each: `keys`, `lineages`, `classes` (a class index),
//! `labels` (an int id, or `None` for no label), `x` `(M, n)`, `P` `(M, n, n)`, `mu`
//! `(M,)` and `class_probs` `(K,)` float64 arrays, and `existence` (`None`: not in the
//! existence table, which counts as 1). Returns `None` when nothing merges, else the
//! merged hypotheses as `(keys (sorted), log_weights, rates)`, most probable first.

use std::sync::Arc;

use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::mhf::hypotheses::{Hypothesis, KeyMap};
use crate::mhf::similar;
use crate::mhf::state::{FilterState, Key, Version};
use crate::python::run;

/// The merged hypotheses: keys (sorted), log weights, rates.
type MergedLists = (Vec<Vec<u64>>, Vec<f64>, Vec<f64>);

/// `ValueError` unless `got` values were given for `expected` entries.
fn expect_count(name: &str, got: usize, expected: usize, per: &str) -> PyResult<()> {
    if got == expected {
        Ok(())
    } else {
        Err(PyValueError::new_err(format!(
            "{name}: expected {expected} values (one per {per}), got {got}"
        )))
    }
}

/// `ValueError` unless an array has `expected` shape.
fn expect_array_shape(name: &str, key: Key, got: &[usize], expected: &[usize]) -> PyResult<()> {
    if got == expected {
        Ok(())
    } else {
        Err(PyValueError::new_err(format!(
            "{name} of version {key}: expected shape {expected:?}, got {got:?}"
        )))
    }
}

/// Twins merged (`semwm.mhf.similar.merge_similar`); the arguments are described in the
/// module documentation.
#[pyfunction]
#[pyo3(signature = (
    hypothesis_keys, log_weights, rates,
    keys, lineages, classes, labels, x, p, mu, class_probs, existence,
    max_distance,
))]
#[allow(clippy::too_many_arguments)] // one list per field of the versions, for the test
pub fn merge_similar(
    py: Python<'_>,
    hypothesis_keys: Vec<Vec<u64>>,
    log_weights: Vec<f64>,
    rates: Vec<f64>,
    keys: Vec<u64>,
    lineages: Vec<u64>,
    classes: Vec<usize>,
    labels: Vec<Option<u32>>,
    x: Vec<PyReadonlyArray2<'_, f64>>,
    p: Vec<PyReadonlyArray3<'_, f64>>,
    mu: Vec<PyReadonlyArray1<'_, f64>>,
    class_probs: Vec<PyReadonlyArray1<'_, f64>>,
    existence: Vec<Option<f64>>,
    max_distance: f64,
) -> PyResult<Option<MergedLists>> {
    let count = hypothesis_keys.len();
    expect_count("log_weights", log_weights.len(), count, "hypothesis")?;
    expect_count("rates", rates.len(), count, "hypothesis")?;
    let hypotheses: Vec<Hypothesis> = hypothesis_keys
        .into_iter()
        .zip(log_weights)
        .zip(rates)
        .map(|((mut held, log_weight), rate)| {
            held.sort_unstable();
            held.dedup();
            Hypothesis {
                log_weight,
                keys: held,
                rate,
            }
        })
        .collect();
    let versions_count = keys.len();
    for (name, got) in [
        ("lineages", lineages.len()),
        ("classes", classes.len()),
        ("labels", labels.len()),
        ("x", x.len()),
        ("P", p.len()),
        ("mu", mu.len()),
        ("class_probs", class_probs.len()),
        ("existence", existence.len()),
    ] {
        expect_count(name, got, versions_count, "version")?;
    }
    let mut versions: KeyMap<Key, Arc<Version>> = KeyMap::default();
    let mut existence_of: KeyMap<Key, f64> = KeyMap::default();
    for i in 0..versions_count {
        let key = keys[i];
        let shape = x[i].shape().to_vec();
        let (modes, size) = (shape[0], shape[1]);
        expect_array_shape("P", key, p[i].shape(), &[modes, size, size])?;
        expect_array_shape("mu", key, mu[i].shape(), &[modes])?;
        let version = Version {
            key,
            lineage: lineages[i],
            cls: classes[i],
            label: labels[i].map(|id| Arc::from(id.to_string())),
            state: Arc::new(FilterState {
                modes,
                size,
                x: x[i].as_array().iter().copied().collect(),
                p: p[i].as_array().iter().copied().collect(),
                mu: mu[i].as_array().iter().copied().collect(),
            }),
            time: 0.0,
            last_seen: 0.0,
            created: 0.0,
            rate: 0.0,
            class_probs: class_probs[i].as_array().iter().copied().collect(),
            sources: Arc::from(Vec::new()),
        };
        if versions.insert(key, Arc::new(version)).is_some() {
            return Err(PyValueError::new_err(format!(
                "keys: version {key} given twice"
            )));
        }
        if let Some(value) = existence[i] {
            existence_of.insert(key, value);
        }
    }
    let merged = run(py, "merge_similar", move || {
        similar::merge_similar(&hypotheses, &versions, &existence_of, max_distance)
    })?;
    Ok(merged.map(|kept| {
        let mut out: MergedLists = (Vec::new(), Vec::new(), Vec::new());
        for h in kept {
            out.0.push(h.keys);
            out.1.push(h.log_weight);
            out.2.push(h.rate);
        }
        out
    }))
}
