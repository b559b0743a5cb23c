//! Lazy prediction of stored object versions to a given time, batched per class filter
//! (`semwm/mhf/predict.py`), and carrying a state over to another class's filter
//! (`conform`).

use std::sync::Arc;

use crate::error::KernelResult;
use crate::filters::batched;
use crate::mhf::existence::{in_view_probability, in_view_reaches, View};
use crate::mhf::state::{FilterState, Version};
use crate::mhf::tables::Tables;

/// One version predicted to the time of a `Predicted`.
#[derive(Debug, Clone)]
pub struct Row {
    pub version: Arc<Version>,
    /// Where its predicted filter state is: its class's batch and its place in it, or
    /// `None` for the version's own (no time passed). Read with [`Row::x`], [`Row::p`],
    /// [`Row::mu`]: a state is made only for the versions a detection updates.
    batch: Option<(Arc<Batch>, usize)>,
    /// `n`: the combined state mean.
    pub mean: Vec<f64>,
}

/// The predicted states of one class's versions, stacked (`m` modes of `n` states).
#[derive(Debug)]
struct Batch {
    modes: usize,
    size: usize,
    x: Vec<f64>,
    p: Vec<f64>,
    mu: Vec<f64>,
}

impl Row {
    /// `(modes, size)` of the predicted state.
    pub fn shape(&self) -> (usize, usize) {
        match &self.batch {
            Some((batch, _)) => (batch.modes, batch.size),
            None => (self.version.state.modes, self.version.state.size),
        }
    }

    /// The predicted state's means, `m x n`.
    pub fn x(&self) -> &[f64] {
        match &self.batch {
            Some((batch, row)) => {
                let width = batch.modes * batch.size;
                &batch.x[row * width..(row + 1) * width]
            }
            None => &self.version.state.x,
        }
    }

    /// The predicted state's covariances, `m x n x n`.
    pub fn p(&self) -> &[f64] {
        match &self.batch {
            Some((batch, row)) => {
                let width = batch.modes * batch.size * batch.size;
                &batch.p[row * width..(row + 1) * width]
            }
            None => &self.version.state.p,
        }
    }

    /// The predicted state's mode probabilities, `m`.
    pub fn mu(&self) -> &[f64] {
        match &self.batch {
            Some((batch, row)) => &batch.mu[row * batch.modes..(row + 1) * batch.modes],
            None => &self.version.state.mu,
        }
    }
}

/// Object versions predicted to one time, in the order they were given, with the
/// combined position `(N, d)` and its covariance `(N, d, d)` stacked.
#[derive(Debug, Clone, Default)]
pub struct Predicted {
    pub rows: Vec<Row>,
    pub dim: usize,
    pub position: Vec<f64>,
    pub covariance: Vec<f64>,
}

impl Predicted {
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Row `i`'s combined position (`d`).
    pub fn position(&self, i: usize) -> &[f64] {
        &self.position[i * self.dim..(i + 1) * self.dim]
    }

    /// Row `i`'s position covariance (`d x d`).
    pub fn covariance(&self, i: usize) -> &[f64] {
        let dd = self.dim * self.dim;
        &self.covariance[i * dd..(i + 1) * dd]
    }

    /// The probability that row `i` lies in `view` (`in_view_probability`), the view
    /// eroded by `margin` (m) if given.
    pub fn in_view(&self, i: usize, view: &View, margin: Option<f64>) -> KernelResult<f64> {
        in_view_probability(self.position(i), self.covariance(i), self.dim, view, margin)
    }

    /// Whether row `i` lies in `view` with probability `level` or more
    /// (`in_view(i, view, None) >= level`, [`in_view_reaches`]).
    pub fn in_view_reaches(&self, i: usize, view: &View, level: f64) -> KernelResult<bool> {
        in_view_reaches(self.position(i), self.covariance(i), self.dim, view, level)
    }

    /// Row `i`'s predicted velocity (`d`): its combined mean's entries after the
    /// position, zero for a filter without velocity (`Predicted.velocity`).
    pub fn velocity(&self, i: usize) -> Vec<f64> {
        let d = self.dim;
        let mean = &self.rows[i].mean;
        if mean.len() >= 2 * d {
            mean[d..2 * d].to_vec()
        } else {
            vec![0.0; d]
        }
    }

    /// The predictions of `rows`, in that order (`Predicted.subset`).
    pub fn subset(&self, rows: &[usize]) -> Predicted {
        let (d, dd) = (self.dim, self.dim * self.dim);
        let mut result = Predicted {
            rows: Vec::with_capacity(rows.len()),
            dim: d,
            position: Vec::with_capacity(rows.len() * d),
            covariance: Vec::with_capacity(rows.len() * dd),
        };
        for &i in rows {
            result.rows.push(self.rows[i].clone());
            result.position.extend_from_slice(self.position(i));
            result
                .covariance
                .extend_from_slice(&self.covariance[i * dd..(i + 1) * dd]);
        }
        result
    }

    /// Each row's position standard deviation (m): the square root of its largest
    /// position variance (`MultipleHypothesisFilter._spread`).
    pub fn spread(&self) -> Vec<f64> {
        let d = self.dim;
        (0..self.len())
            .map(|i| {
                let p = self.covariance(i);
                // numpy's max and maximum: a NaN variance makes the spread NaN
                let diagonal = (0..d).map(|a| p[a * d + a]);
                if diagonal.clone().any(f64::is_nan) {
                    return f64::NAN;
                }
                diagonal.fold(f64::NEG_INFINITY, f64::max).max(0.0).sqrt()
            })
            .collect()
    }
}

/// The combined (moment-matched) mean `n` and covariance `n x n` of a filter state.
pub fn combined(state: &FilterState) -> (Vec<f64>, Vec<f64>) {
    let n = state.size;
    let mut mean = vec![0.0; n];
    let mut covariance = vec![0.0; n * n];
    batched::combine(
        &state.x,
        &state.p,
        &state.mu,
        state.modes,
        n,
        &mut mean,
        &mut covariance,
    );
    (mean, covariance)
}

/// Carries a state over to class `target`'s filter when its structure differs
/// (`conform`): the combined position (and velocity, when both filters have one) and
/// their covariances are kept; the other entries start as a new object's would.
pub fn conform(state: &FilterState, tables: &Tables, target: usize) -> FilterState {
    let spec = &tables.classes[target];
    let (modes, size) = (spec.filter.modes, spec.filter.state);
    if state.modes == modes && state.size == size {
        return state.clone();
    }
    let (mean, covariance) = combined(state);
    let keep = state.size.min(size);
    let mut x = vec![0.0; size];
    x[..keep].copy_from_slice(&mean[..keep]);
    let mut p = spec.initial_covariance.clone();
    for a in 0..keep {
        for b in 0..keep {
            p[a * size + b] = covariance[a * state.size + b];
        }
    }
    FilterState {
        modes,
        size,
        x: x.repeat(modes),
        p: p.repeat(modes),
        mu: spec.initial_mode_probabilities.clone(),
    }
}

/// Predicts every version to `time` (s), one batched call per class filter
/// (`predict_tracks`).
pub fn predict(versions: &[Arc<Version>], time: f64, tables: &Tables) -> KernelResult<Predicted> {
    let d = tables.dim;
    let count = versions.len();
    let mut rows: Vec<Option<Row>> = vec![None; count];
    let mut position = vec![0.0; count * d];
    let mut covariance = vec![0.0; count * d * d];
    // the classes in order of first appearance, each with its members
    let mut groups: Vec<(usize, Vec<usize>)> = Vec::new();
    for (i, version) in versions.iter().enumerate() {
        match groups.iter_mut().find(|(cls, _)| *cls == version.cls) {
            Some((_, members)) => members.push(i),
            None => groups.push((version.cls, vec![i])),
        }
    }
    for (cls, members) in groups {
        let filter = &tables.classes[cls].filter;
        let (m, n) = (filter.modes, filter.state);
        let mut x = Vec::with_capacity(members.len() * m * n);
        let mut p = Vec::with_capacity(members.len() * m * n * n);
        let mut mu = Vec::with_capacity(members.len() * m);
        let mut dt = Vec::with_capacity(members.len());
        for &i in &members {
            let version = &versions[i];
            let state = &version.state;
            if state.modes == m && state.size == n {
                x.extend_from_slice(&state.x);
                p.extend_from_slice(&state.p);
                mu.extend_from_slice(&state.mu);
            } else {
                let conformed = conform(state, tables, cls);
                x.extend_from_slice(&conformed.x);
                p.extend_from_slice(&conformed.p);
                mu.extend_from_slice(&conformed.mu);
            }
            dt.push(time - version.time);
        }
        filter.predict(&mut x, &mut p, &mut mu, &dt)?;
        let batch = Arc::new(Batch {
            modes: m,
            size: n,
            x,
            p,
            mu,
        });
        for (row, &i) in members.iter().enumerate() {
            let version = &versions[i];
            let moved = dt[row] > 0.0;
            let unchanged = version.state.modes == m && version.state.size == n && !moved;
            let mut predicted = Row {
                version: version.clone(),
                batch: (!unchanged).then(|| (batch.clone(), row)),
                mean: vec![0.0; n],
            };
            let (modes, _) = predicted.shape();
            let mut mean = std::mem::take(&mut predicted.mean);
            batched::combine_position(
                predicted.x(),
                predicted.p(),
                predicted.mu(),
                (modes, n, d),
                &mut mean,
                &mut covariance[i * d * d..(i + 1) * d * d],
            );
            position[i * d..(i + 1) * d].copy_from_slice(&mean[..d]);
            predicted.mean = mean;
            rows[i] = Some(predicted);
        }
    }
    Ok(Predicted {
        rows: rows.into_iter().flatten().collect(),
        dim: d,
        position,
        covariance,
    })
}
