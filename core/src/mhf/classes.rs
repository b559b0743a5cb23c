//! Class as a distribution (`semwm/mhf/classes.py`): each detector's confusion
//! likelihoods, a new object's class distribution, and the published class.
//!
//! ```text
//! p'(c) ∝ p(c) L(C(z) | c),        L_class(o, z) = sum_c p(c) L(C(z) | c)
//! ```
//!
//! The published class is the most specific class whose subtree holds more than half
//! the probability (`PUBLISH_MASS`).

use crate::mhf::tables::{ClassId, DetectorId, Tables};

/// A class is published when its subtree holds more than this probability.
pub const PUBLISH_MASS: f64 = 0.5;

/// `sum` as numpy's `add.reduce` computes it over a contiguous row: pairwise, with
/// eight partial sums (numpy's `pairwise_sum`), so that sums of the Python engine's
/// arrays match to the last bit.
pub fn numpy_sum(values: &[f64]) -> f64 {
    let n = values.len();
    if n < 8 {
        let mut total = 0.0;
        for &v in values {
            total += v;
        }
        total
    } else if n <= 128 {
        let mut r = [0.0; 8];
        r.copy_from_slice(&values[..8]);
        let mut i = 8;
        while i < n - n % 8 {
            for j in 0..8 {
                r[j] += values[i + j];
            }
            i += 8;
        }
        let mut total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        while i < n {
            total += values[i];
            i += 1;
        }
        total
    } else {
        let mut half = n / 2;
        half -= half % 8;
        numpy_sum(&values[..half]) + numpy_sum(&values[half..])
    }
}

/// `L(reported | c)` of `detector` for every class `c` (`K`).
pub fn likelihood(tables: &Tables, detector: DetectorId, reported: ClassId) -> &[f64] {
    let k = tables.class_count();
    &tables.detectors[detector].likelihood[reported * k..(reported + 1) * k]
}

/// The class distribution of a new object started by a report (`ClassModel.initial`):
/// the uniform prior over the classes that can appear, times the report's likelihood;
/// the report itself where no class that can appear explains it.
pub fn initial(tables: &Tables, detector: DetectorId, reported: ClassId) -> Vec<f64> {
    let mut weights: Vec<f64> = likelihood(tables, detector, reported)
        .iter()
        .zip(&tables.appear_mask)
        .map(|(l, mask)| l * mask)
        .collect();
    let total = numpy_sum(&weights);
    if total <= 0.0 {
        return point(tables, reported);
    }
    for weight in &mut weights {
        *weight /= total;
    }
    weights
}

/// A distribution sitting on one class.
pub fn point(tables: &Tables, class: ClassId) -> Vec<f64> {
    let mut result = vec![0.0; tables.class_count()];
    result[class] = 1.0;
    result
}

/// The published class of a distribution (`ClassModel.published_many`, one row): among
/// the classes whose subtree holds more than `PUBLISH_MASS`, the deepest wins, then the
/// larger mass, then the first; with none, the most probable class.
pub fn published(tables: &Tables, probabilities: &[f64]) -> ClassId {
    let k = tables.class_count();
    let mut best: Option<(f64, ClassId)> = None;
    for i in 0..k {
        let row = &tables.subtree[i * k..(i + 1) * k];
        let mut mass = 0.0;
        for j in 0..k {
            mass += probabilities[j] * row[j];
        }
        if mass > PUBLISH_MASS + 1e-12 {
            let score = tables.depth[i] * 4.0 + mass;
            if best.is_none_or(|(top, _)| score > top) {
                best = Some((score, i));
            }
        }
    }
    if let Some((_, class)) = best {
        return class;
    }
    // numpy's argmax: the first of the largest (a NaN wins, as numpy's does)
    let mut chosen = 0;
    for i in 1..k {
        if probabilities[i] > probabilities[chosen] || probabilities[i].is_nan() {
            if probabilities[chosen].is_nan() {
                break;
            }
            chosen = i;
        }
    }
    chosen
}
