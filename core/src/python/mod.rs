//! The Python module `semwm._core`: arrays in, arrays out.
//!
//! Every function copies its inputs into owned buffers (the arrays are small: a few
//! doubles per object), releases the GIL for the numeric work (`Python::detach`, PyO3's
//! `allow_threads`), and returns new numpy arrays. A kernel error becomes a Python
//! exception with its message (`ValueError` for shapes, `numpy.linalg.LinAlgError` for a
//! matrix that is not positive definite, as the Python engine raises); a panic, which
//! the shape checks are there to rule out, is caught and raised as `RuntimeError`,
//! never unwound into Python. No `unsafe` here.

mod engine;
mod published;
mod rates;
mod reader;
mod scan;
mod similar;

use std::panic::{catch_unwind, AssertUnwindSafe};

use numpy::ndarray::{Array, ArrayView, Dimension, IntoDimension};
use numpy::{
    IntoPyArray, PyArray, PyArray1, PyArray2, PyArray3, PyArray4, PyArrayMethods, PyReadonlyArray1,
    PyReadonlyArray2, PyReadonlyArray3, PyReadonlyArray4,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyType;

use crate::error::{expect_shape, KernelError, KernelResult};
use crate::filters::batched;
use crate::filters::factory::{ClassTables, TransitionPeriod};
use crate::filters::small;
use crate::mhf::coverage;
use crate::mhf::existence;
use crate::mhf::expansion::{
    self, ClusterArrays, EntryArrays, ExpandedArrays, OptionArrays, ScanArrays, TrackArrays,
};
use crate::mhf::hypotheses;

/// A kernel error as the Python exception the Python engine would raise.
fn to_py_err(py: Python<'_>, error: KernelError) -> PyErr {
    match error {
        KernelError::Shape(message) | KernelError::Value(message) => PyValueError::new_err(message),
        KernelError::NotPositiveDefinite(message) | KernelError::Singular(message) => {
            match py
                .import("numpy.linalg")
                .and_then(|module| module.getattr("LinAlgError"))
                .and_then(|class| class.cast_into::<PyType>().map_err(PyErr::from))
            {
                Ok(class) => PyErr::from_type(class, message),
                Err(import_error) => import_error,
            }
        }
    }
}

/// Runs `work` without the GIL, with panics caught: the one way kernels are called.
pub(crate) fn run<T: Send>(
    py: Python<'_>,
    name: &str,
    work: impl FnOnce() -> KernelResult<T> + Send,
) -> PyResult<T> {
    let outcome = py.detach(|| catch_unwind(AssertUnwindSafe(work)));
    match outcome {
        Ok(Ok(value)) => Ok(value),
        Ok(Err(error)) => Err(to_py_err(py, error)),
        Err(panic) => {
            let message = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".to_string());
            Err(PyRuntimeError::new_err(format!(
                "semwm._core.{name}: internal error (a bug, please report): {message}"
            )))
        }
    }
}

/// An array's values in row-major order, with its shape.
fn values<D: Dimension>(array: &Bound<'_, PyArray<f64, D>>) -> PyResult<(Vec<f64>, Vec<usize>)> {
    let readonly = array.try_readonly()?;
    let view = readonly.as_array();
    Ok((view.iter().copied().collect(), view.shape().to_vec()))
}

/// A read-only array's values in row-major order.
fn flat<D: Dimension>(array: ArrayView<'_, f64, D>) -> Vec<f64> {
    array.iter().copied().collect()
}

fn to_numpy<'py, Sh: IntoDimension>(
    py: Python<'py>,
    shape: Sh,
    data: Vec<f64>,
) -> PyResult<Bound<'py, PyArray<f64, Sh::Dim>>> {
    Array::from_shape_vec(shape, data)
        .map(|array| array.into_pyarray(py))
        .map_err(|error| PyRuntimeError::new_err(format!("semwm._core: result shape: {error}")))
}

/// The stacked states of `N` objects: `x` `(N, M, n)`, `P` `(N, M, n, n)`, `mu` `(N, M)`.
struct States {
    x: Vec<f64>,
    p: Vec<f64>,
    mu: Vec<f64>,
    count: usize,
    modes: usize,
    state: usize,
}

impl States {
    fn read(
        x: &Bound<'_, PyArray3<f64>>,
        p: &Bound<'_, PyArray4<f64>>,
        mu: &Bound<'_, PyArray2<f64>>,
    ) -> PyResult<Self> {
        let (x, shape) = values(x)?;
        let (count, modes, state) = (shape[0], shape[1], shape[2]);
        let (p, p_shape) = values(p)?;
        let (mu, mu_shape) = values(mu)?;
        let check = || -> KernelResult<()> {
            expect_shape("P", &p_shape, &[count, modes, state, state])?;
            expect_shape("mu", &mu_shape, &[count, modes])?;
            if modes == 0 || modes > batched::MAX_MODES || state == 0 || state > small::MAX_STATE {
                return Err(KernelError::Shape(format!(
                    "x: expected 1 to {} modes of 1 to {} state entries, got shape {shape:?}",
                    batched::MAX_MODES,
                    small::MAX_STATE
                )));
            }
            Ok(())
        };
        check().map_err(shape_error)?;
        Ok(States {
            x,
            p,
            mu,
            count,
            modes,
            state,
        })
    }

    #[allow(clippy::type_complexity)]
    fn into_numpy<'py>(
        self,
        py: Python<'py>,
    ) -> PyResult<(
        Bound<'py, PyArray3<f64>>,
        Bound<'py, PyArray4<f64>>,
        Bound<'py, PyArray2<f64>>,
    )> {
        let (n, m, s) = (self.count, self.modes, self.state);
        Ok((
            to_numpy(py, (n, m, s), self.x)?,
            to_numpy(py, (n, m, s, s), self.p)?,
            to_numpy(py, (n, m), self.mu)?,
        ))
    }
}

/// `ValueError` from a shape check (the arguments are checked before any work).
fn shape_error(error: KernelError) -> PyErr {
    PyValueError::new_err(error.to_string())
}

/// `(period, lam, V, V_inv)` of a transition stated for a period.
type PeriodArgs<'py> = (
    f64,
    PyReadonlyArray1<'py, f64>,
    PyReadonlyArray2<'py, f64>,
    PyReadonlyArray2<'py, f64>,
);

/// One class's filter: the numeric tables of `semwm.filters.factory.ClassFilter`, handed
/// over once per class, and its batched prediction.
#[pyclass(frozen, name = "ClassFilter", module = "semwm._core")]
pub(crate) struct PyClassFilter {
    pub(crate) tables: ClassTables,
}

#[pymethods]
impl PyClassFilter {
    /// `F0`, `F1` `(M, n, n)`; `C` `(4, M, n, n)`; `transition` `(M, M)`;
    /// `first_order` `M` flags; `velocity_decay` (m/s^2); `period` (s) with the
    /// eigen-decomposition `lam` `(M,)`, `V`, `V_inv` `(M, M)` of `transition`, or `None`.
    #[new]
    #[pyo3(signature = (dim, f0, f1, c, transition, first_order, velocity_decay, period=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        dim: usize,
        f0: PyReadonlyArray3<'_, f64>,
        f1: PyReadonlyArray3<'_, f64>,
        c: PyReadonlyArray4<'_, f64>,
        transition: PyReadonlyArray2<'_, f64>,
        first_order: Vec<bool>,
        velocity_decay: f64,
        period: Option<PeriodArgs<'_>>,
    ) -> PyResult<Self> {
        let shape = f0.as_array().shape().to_vec();
        if shape.len() != 3 || shape[1] != shape[2] {
            return Err(PyValueError::new_err(format!(
                "F0: expected shape (M, n, n), got {shape:?}"
            )));
        }
        let tables = ClassTables {
            dim,
            modes: shape[0],
            state: shape[1],
            f0: flat(f0.as_array()),
            f1: flat(f1.as_array()),
            c: flat(c.as_array()),
            transition: flat(transition.as_array()),
            period: period.map(|(period, lam, v, v_inv)| TransitionPeriod {
                period,
                lam: flat(lam.as_array()),
                v: flat(v.as_array()),
                v_inv: flat(v_inv.as_array()),
            }),
            velocity_decay,
            first_order,
        };
        tables.validate().map_err(shape_error)?;
        Ok(PyClassFilter { tables })
    }

    /// Predicts each object by its own `dt` (s): `ClassFilter.predict`. Returns new
    /// `x`, `P`, `mu`.
    #[allow(clippy::type_complexity)]
    fn predict<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyArray3<f64>>,
        p: &Bound<'py, PyArray4<f64>>,
        mu: &Bound<'py, PyArray2<f64>>,
        dt: &Bound<'py, PyArray1<f64>>,
    ) -> PyResult<(
        Bound<'py, PyArray3<f64>>,
        Bound<'py, PyArray4<f64>>,
        Bound<'py, PyArray2<f64>>,
    )> {
        let mut states = States::read(x, p, mu)?;
        let (dt, _) = values(dt)?;
        let tables = &self.tables;
        if (states.modes, states.state) != (tables.modes, tables.state) {
            return Err(PyValueError::new_err(format!(
                "x: expected (N, {}, {}) for this filter, got (N, {}, {})",
                tables.modes, tables.state, states.modes, states.state
            )));
        }
        if dt.len() != states.count {
            return Err(PyValueError::new_err(format!(
                "dt: expected {} time steps (one per object), got {}",
                states.count,
                dt.len()
            )));
        }
        run(py, "ClassFilter.predict", || {
            tables.predict(&mut states.x, &mut states.p, &mut states.mu, &dt)?;
            Ok(states)
        })?
        .into_numpy(py)
    }

    #[getter]
    fn modes(&self) -> usize {
        self.tables.modes
    }

    #[getter]
    fn state_size(&self) -> usize {
        self.tables.state
    }
}

/// IMM mixing (`semwm.filters.batched.imm_mix`): `T` `(M, M)` or `(N, M, M)`. Returns
/// the mixed `x0`, `P0` and the predicted mode probabilities `cbar`.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn imm_mix<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyArray3<f64>>,
    p: &Bound<'py, PyArray4<f64>>,
    mu: &Bound<'py, PyArray2<f64>>,
    t: &Bound<'py, PyAny>,
) -> PyResult<(
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray4<f64>>,
    Bound<'py, PyArray2<f64>>,
)> {
    let mut states = States::read(x, p, mu)?;
    let (t, per_object) = transitions(t, states.count, states.modes)?;
    run(py, "imm_mix", || {
        let (m, n) = (states.modes, states.state);
        let mut x0 = vec![0.0; m * n];
        let mut p0 = vec![0.0; m * n * n];
        let mut cbar = vec![0.0; m];
        for i in 0..states.count {
            let ti = if per_object {
                &t[i * m * m..(i + 1) * m * m]
            } else {
                &t[..]
            };
            let (xs, ps, mus) = object(&mut states, i);
            batched::imm_mix(xs, ps, mus, ti, m, n, &mut x0, &mut p0, &mut cbar);
            xs.copy_from_slice(&x0);
            ps.copy_from_slice(&p0);
            mus.copy_from_slice(&cbar);
        }
        Ok(states)
    })?
    .into_numpy(py)
}

/// IMM prediction with given models (`semwm.filters.batched.predict`): `F`, `Q`
/// `(N, M, n, n)`, `T` `(M, M)` or `(N, M, M)`.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn predict<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyArray3<f64>>,
    p: &Bound<'py, PyArray4<f64>>,
    mu: &Bound<'py, PyArray2<f64>>,
    f: &Bound<'py, PyArray4<f64>>,
    q: &Bound<'py, PyArray4<f64>>,
    t: &Bound<'py, PyAny>,
) -> PyResult<(
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray4<f64>>,
    Bound<'py, PyArray2<f64>>,
)> {
    let mut states = States::read(x, p, mu)?;
    let (m, n) = (states.modes, states.state);
    let (f, f_shape) = values(f)?;
    let (q, q_shape) = values(q)?;
    let expected = [states.count, m, n, n];
    expect_shape("F", &f_shape, &expected).map_err(shape_error)?;
    expect_shape("Q", &q_shape, &expected).map_err(shape_error)?;
    let (t, per_object) = transitions(t, states.count, m)?;
    run(py, "predict", || {
        let mnn = m * n * n;
        let mut x0 = vec![0.0; m * n];
        let mut p0 = vec![0.0; mnn];
        let mut cbar = vec![0.0; m];
        for i in 0..states.count {
            let ti = if per_object {
                &t[i * m * m..(i + 1) * m * m]
            } else {
                &t[..]
            };
            let (xs, ps, mus) = object(&mut states, i);
            batched::imm_mix(xs, ps, mus, ti, m, n, &mut x0, &mut p0, &mut cbar);
            let (fi, qi) = (&f[i * mnn..(i + 1) * mnn], &q[i * mnn..(i + 1) * mnn]);
            batched::predict_modes(&mut x0, &mut p0, fi, qi, m, n);
            xs.copy_from_slice(&x0);
            ps.copy_from_slice(&p0);
            mus.copy_from_slice(&cbar);
        }
        Ok(states)
    })?
    .into_numpy(py)
}

/// `T` as values, and whether it is one matrix per object.
fn transitions(t: &Bound<'_, PyAny>, count: usize, modes: usize) -> PyResult<(Vec<f64>, bool)> {
    if let Ok(one) = t.cast::<PyArray2<f64>>() {
        let (values, shape) = values(one)?;
        expect_shape("T", &shape, &[modes, modes]).map_err(shape_error)?;
        return Ok((values, false));
    }
    if let Ok(each) = t.cast::<PyArray3<f64>>() {
        let (values, shape) = values(each)?;
        expect_shape("T", &shape, &[count, modes, modes]).map_err(shape_error)?;
        return Ok((values, true));
    }
    Err(PyValueError::new_err(format!(
        "T: expected a float64 array of shape ({modes}, {modes}) or ({count}, {modes}, {modes})"
    )))
}

/// Object `i`'s `x`, `P`, `mu` slices.
fn object(states: &mut States, i: usize) -> (&mut [f64], &mut [f64], &mut [f64]) {
    let (m, n) = (states.modes, states.state);
    (
        &mut states.x[i * m * n..(i + 1) * m * n],
        &mut states.p[i * m * n * n..(i + 1) * m * n * n],
        &mut states.mu[i * m..(i + 1) * m],
    )
}

/// IMM update (`semwm.filters.batched.update`): `z` `(N, d)`, `R` `(N, d, d)`. Returns
/// the updated `x`, `P`, `mu` and the log likelihood `(N,)`.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn update<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyArray3<f64>>,
    p: &Bound<'py, PyArray4<f64>>,
    mu: &Bound<'py, PyArray2<f64>>,
    z: &Bound<'py, PyArray2<f64>>,
    r: &Bound<'py, PyArray3<f64>>,
) -> PyResult<(
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray4<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
)> {
    let mut states = States::read(x, p, mu)?;
    let (z, z_shape) = values(z)?;
    let (r, r_shape) = values(r)?;
    let count = states.count;
    let d = z_shape.get(1).copied().unwrap_or(0);
    let check = || -> KernelResult<()> {
        expect_shape("z", &z_shape, &[count, d])?;
        expect_shape("R", &r_shape, &[count, d, d])?;
        if d == 0 || d > 3 || d > states.state {
            return Err(KernelError::Shape(format!(
                "z: expected 1 to min(3, n = {}) measured entries, got {d}",
                states.state
            )));
        }
        Ok(())
    };
    check().map_err(shape_error)?;
    let (states, log_lik) = run(py, "update", || {
        let (m, n) = (states.modes, states.state);
        let mut log_lik = vec![0.0; count];
        for (i, value) in log_lik.iter_mut().enumerate() {
            let (zi, ri) = (&z[i * d..(i + 1) * d], &r[i * d * d..(i + 1) * d * d]);
            let (xs, ps, mus) = object(&mut states, i);
            *value = batched::update(xs, ps, mus, zi, ri, m, n, d)?;
        }
        Ok((states, log_lik))
    })?;
    let (x, p, mu) = states.into_numpy(py)?;
    Ok((x, p, mu, to_numpy(py, count, log_lik)?))
}

/// The IMM's combined estimate (`semwm.filters.batched.combine`): `(N, n)`, `(N, n, n)`.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn combine<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyArray3<f64>>,
    p: &Bound<'py, PyArray4<f64>>,
    mu: &Bound<'py, PyArray2<f64>>,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray3<f64>>)> {
    let states = States::read(x, p, mu)?;
    let (count, m, n) = (states.count, states.modes, states.state);
    let (x_hat, p_hat) = run(py, "combine", || {
        let mut x_hat = vec![0.0; count * n];
        let mut p_hat = vec![0.0; count * n * n];
        for i in 0..count {
            batched::combine(
                &states.x[i * m * n..(i + 1) * m * n],
                &states.p[i * m * n * n..(i + 1) * m * n * n],
                &states.mu[i * m..(i + 1) * m],
                m,
                n,
                &mut x_hat[i * n..(i + 1) * n],
                &mut p_hat[i * n * n..(i + 1) * n * n],
            );
        }
        Ok((x_hat, p_hat))
    })?;
    Ok((
        to_numpy(py, (count, n), x_hat)?,
        to_numpy(py, (count, n, n), p_hat)?,
    ))
}

/// Squared Mahalanobis distances, the gate (`semwm.filters.small.mahalanobis_squared`):
/// residuals `(K, d)` and covariances `(K, d, d)`; returns `(K,)`.
#[pyfunction]
fn mahalanobis_squared<'py>(
    py: Python<'py>,
    residual: &Bound<'py, PyArray2<f64>>,
    covariance: &Bound<'py, PyArray3<f64>>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (r, r_shape) = values(residual)?;
    let (c, c_shape) = values(covariance)?;
    let (count, d) = (r_shape[0], r_shape[1]);
    let check = || -> KernelResult<()> {
        expect_shape("covariance", &c_shape, &[count, d, d])?;
        if d == 0 || d > small::MAX_STATE {
            return Err(KernelError::Shape(format!(
                "residual: expected 1 to {} entries, got {d}",
                small::MAX_STATE
            )));
        }
        Ok(())
    };
    check().map_err(shape_error)?;
    let distances = run(py, "mahalanobis_squared", || {
        (0..count)
            .map(|i| {
                small::mahalanobis_squared(
                    &r[i * d..(i + 1) * d],
                    &c[i * d * d..(i + 1) * d * d],
                    d,
                )
            })
            .collect::<KernelResult<Vec<f64>>>()
    })?;
    to_numpy(py, count, distances)
}

// ------------------------------------------------ existence and coverage (semwm.mhf)

/// Two `(N,)` arrays: existence and `log q`, or nodes and weights.
type Pair<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>);

/// `Ok` when `values` holds one value per object (`count`), else a `ValueError` naming it.
fn same_length(name: &str, values: &[f64], count: usize) -> PyResult<()> {
    if values.len() == count {
        Ok(())
    } else {
        Err(PyValueError::new_err(format!(
            "{name}: expected {count} values (one per object), got {}",
            values.len()
        )))
    }
}

/// An optional `(N,)` argument, one value per object, copied (`None` stays `None`).
fn per_object(
    name: &str,
    array: Option<&Bound<'_, PyArray1<f64>>>,
    count: usize,
) -> PyResult<Option<Vec<f64>>> {
    match array {
        Some(a) => {
            let (a, _) = values(a)?;
            same_length(name, &a, count)?;
            Ok(Some(a))
        }
        None => Ok(None),
    }
}

/// Existence after `dt` seconds with no detection, and `log q`
/// (`semwm.mhf.existence.survive`): `r`, `mu`, `f` `(N,)`.
#[pyfunction]
fn survive<'py>(
    py: Python<'py>,
    r: &Bound<'py, PyArray1<f64>>,
    mu: &Bound<'py, PyArray1<f64>>,
    f: &Bound<'py, PyArray1<f64>>,
    dt: f64,
) -> PyResult<Pair<'py>> {
    let (r, _) = values(r)?;
    let (mu, _) = values(mu)?;
    let (f, _) = values(f)?;
    let count = r.len();
    same_length("mu", &mu, count)?;
    same_length("f", &f, count)?;
    let (r_new, log_q) = run(py, "survive", || {
        Ok((0..count)
            .map(|i| existence::survive(r[i], mu[i], f[i], dt))
            .unzip::<f64, f64, Vec<f64>, Vec<f64>>())
    })?;
    Ok((to_numpy(py, count, r_new)?, to_numpy(py, count, log_q)?))
}

/// Existence after a scan that could have reported each object with probability `p` and
/// did not, and `log q` (`semwm.mhf.existence.missed`): `r`, `p` `(N,)`.
#[pyfunction]
fn missed<'py>(
    py: Python<'py>,
    r: &Bound<'py, PyArray1<f64>>,
    p: &Bound<'py, PyArray1<f64>>,
) -> PyResult<Pair<'py>> {
    let (r, _) = values(r)?;
    let (p, _) = values(p)?;
    let count = r.len();
    same_length("p_detect", &p, count)?;
    let (r_new, log_q) = run(py, "missed", || {
        Ok((0..count)
            .map(|i| existence::missed(r[i], p[i]))
            .unzip::<f64, f64, Vec<f64>, Vec<f64>>())
    })?;
    Ok((to_numpy(py, count, r_new)?, to_numpy(py, count, log_q)?))
}

/// Positions `(N, d)` and covariances `(N, d, d)`, checked.
fn estimates(
    position: &Bound<'_, PyArray2<f64>>,
    covariance: &Bound<'_, PyArray3<f64>>,
) -> PyResult<(Vec<f64>, Vec<f64>, usize, usize)> {
    let (x, x_shape) = values(position)?;
    let (p, p_shape) = values(covariance)?;
    let (count, d) = (x_shape[0], x_shape[1]);
    expect_shape("covariance", &p_shape, &[count, d, d]).map_err(shape_error)?;
    Ok((x, p, count, d))
}

/// The probability that each object lies inside the box `[low, high]` widened by its
/// `margin` `(N, d)` (`semwm.mhf.existence.inside_probability`): `position` `(N, d)`,
/// `covariance` `(N, d, d)`, `low`, `high` `(d,)`. Returns `(N,)`.
#[pyfunction]
#[pyo3(signature = (position, covariance, low, high, margin=None))]
fn inside_probability<'py>(
    py: Python<'py>,
    position: &Bound<'py, PyArray2<f64>>,
    covariance: &Bound<'py, PyArray3<f64>>,
    low: &Bound<'py, PyArray1<f64>>,
    high: &Bound<'py, PyArray1<f64>>,
    margin: Option<&Bound<'py, PyArray2<f64>>>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (x, p, count, d) = estimates(position, covariance)?;
    let (low, low_shape) = values(low)?;
    let (high, high_shape) = values(high)?;
    expect_shape("region (lower corner)", &low_shape, &[d]).map_err(shape_error)?;
    expect_shape("region (upper corner)", &high_shape, &[d]).map_err(shape_error)?;
    let margin = match margin {
        Some(m) => {
            let (m, m_shape) = values(m)?;
            expect_shape("margin", &m_shape, &[count, d]).map_err(shape_error)?;
            Some(m)
        }
        None => None,
    };
    let result = run(py, "inside_probability", || {
        Ok((0..count)
            .map(|i| {
                existence::inside_probability(
                    &x[i * d..(i + 1) * d],
                    &p[i * d * d..(i + 1) * d * d],
                    &low,
                    &high,
                    margin.as_ref().map(|m| &m[i * d..(i + 1) * d]),
                )
            })
            .collect::<Vec<f64>>())
    })?;
    to_numpy(py, count, result)
}

/// The probability that each object lies in a sensor's view
/// (`semwm.mhf.existence.in_view_probability`, 7 x 7 Gauss-Hermite): `position`
/// `(N, d)`, `covariance` `(N, d, d)`, `d >= 2`; the view's `sensor` position (its first
/// two entries), `heading` (rad), `range` (m) and `half_angle` (rad), either `None`; `margin`
/// `(N,)` (m) or `None`: the view eroded by each object's margin.
#[pyfunction]
#[pyo3(signature = (position, covariance, sensor, heading, range=None, half_angle=None, margin=None))]
#[allow(clippy::too_many_arguments)] // the Python signature: one argument per part of the view
fn in_view_probability<'py>(
    py: Python<'py>,
    position: &Bound<'py, PyArray2<f64>>,
    covariance: &Bound<'py, PyArray3<f64>>,
    sensor: &Bound<'py, PyArray1<f64>>,
    heading: f64,
    range: Option<f64>,
    half_angle: Option<f64>,
    margin: Option<&Bound<'py, PyArray1<f64>>>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (x, p, count, d) = estimates(position, covariance)?;
    let (sensor, _) = values(sensor)?;
    let margin = per_object("margin", margin, count)?;
    if d < 2 || sensor.len() < 2 {
        return Err(PyValueError::new_err(format!(
            "position and sensor: expected at least 2 entries, got {d} and {}",
            sensor.len()
        )));
    }
    let view = existence::View {
        position: [sensor[0], sensor[1]],
        heading,
        range,
        half_angle,
    };
    let result = run(py, "in_view_probability", || {
        (0..count)
            .map(|i| {
                existence::in_view_probability(
                    &x[i * d..(i + 1) * d],
                    &p[i * d * d..(i + 1) * d * d],
                    d,
                    &view,
                    margin.as_ref().map(|m| m[i]),
                )
            })
            .collect::<KernelResult<Vec<f64>>>()
    })?;
    to_numpy(py, count, result)
}

/// The nodes and weights (normalised) of the 7-point Gauss-Hermite rule the core uses.
#[pyfunction]
fn gauss_hermite_rule<'py>(py: Python<'py>) -> PyResult<Pair<'py>> {
    Ok((
        to_numpy(py, 7, existence::GH_X.to_vec())?,
        to_numpy(py, 7, existence::GH_W.to_vec())?,
    ))
}

/// The standard normal CDF of each value (Cephes `ndtr`, as `scipy.special.ndtr`).
#[pyfunction]
fn ndtr<'py>(
    py: Python<'py>,
    values_: &Bound<'py, PyArray1<f64>>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (v, _) = values(values_)?;
    let count = v.len();
    let result = run(py, "ndtr", || {
        Ok(v.iter().map(|&a| existence::ndtr(a)).collect::<Vec<f64>>())
    })?;
    to_numpy(py, count, result)
}

/// Range coverage of each object (`ObservedRates.watched` with a sensor position and a
/// range, `semwm.mhf.rates.range_coverage`): `positions` `(N, d)`, `sensor` `(k,)`,
/// `reach` (m), `spread` `(N,)` or `None` (a hard cut).
#[pyfunction]
#[pyo3(signature = (positions, sensor, reach, spread=None))]
fn range_coverage<'py>(
    py: Python<'py>,
    positions: &Bound<'py, PyArray2<f64>>,
    sensor: &Bound<'py, PyArray1<f64>>,
    reach: f64,
    spread: Option<&Bound<'py, PyArray1<f64>>>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (x, shape) = values(positions)?;
    let (count, d) = (shape[0], shape[1]);
    let (sensor, _) = values(sensor)?;
    let spread = per_object("spread", spread, count)?;
    let result = run(py, "range_coverage", || {
        Ok((0..count)
            .map(|i| {
                coverage::range_coverage(
                    &x[i * d..(i + 1) * d],
                    &sensor,
                    reach,
                    spread.as_ref().map(|s| s[i]),
                )
            })
            .collect::<Vec<f64>>())
    })?;
    to_numpy(py, count, result)
}

/// How far each point `(N, d)` lies outside the convex hull of `corners` `(M, d)`
/// (`semwm.mhf.rates.hull_distance`).
#[pyfunction]
fn hull_distance<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyArray2<f64>>,
    corners: &Bound<'py, PyArray2<f64>>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (x, shape) = values(points)?;
    let (c, c_shape) = values(corners)?;
    let (count, d) = (shape[0], shape[1]);
    expect_shape("corners", &c_shape, &[c_shape[0], d]).map_err(shape_error)?;
    if c_shape[0] == 0 {
        return Err(shape_error(KernelError::Shape(
            "corners: expected at least one corner".to_string(),
        )));
    }
    let result = run(py, "hull_distance", || {
        Ok(coverage::hull_distance(&x, &c, d))
    })?;
    to_numpy(py, count, result)
}

// ---------------------------------------------------------------- the expansion of a scan

/// The hypothesis algebra of one scan (`core/src/expansion.rs`) for one filter's
/// settings: `MultipleHypothesisFilter`'s eq. (3) ratio and n_hyp,max, its association
/// model and log label error rate, handed over once per filter.
#[pyclass(frozen, name = "ScanExpansion", module = "semwm._core")]
struct PyScanExpansion {
    settings: expansion::Settings,
}

/// Keys, values and labels of the versions (`ScanArrays`' first three).
type TrackArgs = (Vec<u64>, Vec<f64>, Vec<Option<String>>);
/// The given clusters: ids, sizes, hypothesis sizes, keys, log weights, rates.
type ClusterArgs = (
    Vec<usize>,
    Vec<usize>,
    Vec<usize>,
    Vec<u64>,
    Vec<f64>,
    Vec<f64>,
);
/// The options: kinds, labels, keys, values.
type OptionArgs = (Vec<u8>, Vec<Option<String>>, Vec<u64>, Vec<f64>);
/// Counts, keys and values of the options' presence or existing entries.
type EntryArgs = (Vec<usize>, Vec<u64>, Vec<f64>);
/// The result: untouched clusters; new clusters (sizes, key sizes, keys); their
/// hypotheses (sizes, keys, log weights, rates); versions made (kinds, keys, sources,
/// existence); the next key.
type ExpandedResult = (
    Vec<usize>,
    (Vec<usize>, Vec<usize>, Vec<u64>),
    (Vec<usize>, Vec<u64>, Vec<f64>, Vec<f64>),
    (Vec<u8>, Vec<u64>, Vec<u64>, Vec<f64>),
    u64,
);

#[pymethods]
impl PyScanExpansion {
    #[new]
    fn new(
        ratio: f64,
        max_hypotheses: usize,
        association_model: &str,
        log_label_error: f64,
    ) -> PyResult<Self> {
        let mht = match association_model {
            "mht" => true,
            "paper" => false,
            other => {
                return Err(PyValueError::new_err(format!(
                    "association_model: expected 'mht' or 'paper', got {other:?}"
                )))
            }
        };
        if max_hypotheses == 0 {
            return Err(PyValueError::new_err(
                "max_hypotheses: expected at least 1, got 0",
            ));
        }
        Ok(PyScanExpansion {
            settings: expansion::Settings {
                ratio,
                max_hypotheses,
                mht,
                log_label_error,
            },
        })
    }

    /// The scan's clusters from its options (`semwm.mhf.rust_expansion.expand_scan`
    /// packs the arguments, `ScanArrays` names them).
    #[allow(clippy::too_many_arguments)]
    fn scan(
        &self,
        py: Python<'_>,
        counters: (u64, u64, usize),
        tracks: TrackArgs,
        clusters: ClusterArgs,
        options: OptionArgs,
        presence: EntryArgs,
        existing: EntryArgs,
    ) -> PyResult<ExpandedResult> {
        let (keys, rates, labels) = tracks;
        let (ids, sizes, hypothesis_sizes, keys_held, log_weights, hypothesis_rates) = clusters;
        let (kinds, option_labels, option_keys, values) = options;
        let entries = |(counts, keys, values): EntryArgs| EntryArrays {
            counts,
            keys,
            values,
        };
        let arrays = ScanArrays {
            counters,
            tracks: TrackArrays {
                keys,
                rates,
                labels,
            },
            clusters: ClusterArrays {
                ids,
                sizes,
                hypothesis_sizes,
                keys: keys_held,
                log_weights,
                rates: hypothesis_rates,
            },
            options: OptionArrays {
                kinds,
                labels: option_labels,
                keys: option_keys,
                values,
            },
            presence: entries(presence),
            existing: entries(existing),
        };
        let settings = self.settings;
        let out = run(py, "ScanExpansion.scan", move || {
            let scan = arrays.into_scan(settings)?;
            expansion::expand_scan(scan).map(ExpandedArrays::from)
        })?;
        Ok((
            out.untouched,
            (out.cluster_sizes, out.cluster_key_sizes, out.cluster_keys),
            (
                out.hypothesis_sizes,
                out.hypothesis_keys,
                out.log_weights,
                out.rates,
            ),
            (out.op_kinds, out.op_keys, out.op_sources, out.op_existence),
            out.next_key,
        ))
    }
}

/// `merge` then `prune` (`semwm.mhf.prune`) of children given as arrays: per child its
/// number of keys, the keys, log weights and rates. Returns the kept hypotheses in the
/// same layout, most probable first.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn merge_prune(
    py: Python<'_>,
    sizes: Vec<usize>,
    keys: Vec<u64>,
    log_weights: Vec<f64>,
    rates: Vec<f64>,
    ratio: f64,
    max_hypotheses: usize,
) -> PyResult<(Vec<usize>, Vec<u64>, Vec<f64>, Vec<f64>)> {
    run(py, "merge_prune", move || {
        let count = sizes.len();
        for (name, got) in [("log_weights", log_weights.len()), ("rates", rates.len())] {
            if got != count {
                return Err(KernelError::Shape(format!(
                    "{name}: expected {count} values (one per child), got {got}"
                )));
            }
        }
        let total: usize = sizes.iter().sum();
        if total != keys.len() {
            return Err(KernelError::Shape(format!(
                "keys: expected {total} values (the sizes' sum), got {}",
                keys.len()
            )));
        }
        let mut merged = hypotheses::Merged::new();
        let mut at = 0;
        for i in 0..count {
            let mut child = keys[at..at + sizes[i]].to_vec();
            at += sizes[i];
            child.sort_unstable();
            child.dedup();
            merged.add(child, log_weights[i], rates[i]);
        }
        let kept = hypotheses::prune(merged, ratio, max_hypotheses)?;
        let mut out = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for h in kept {
            out.0.push(h.keys.len());
            out.1.extend_from_slice(&h.keys);
            out.2.push(h.log_weight);
            out.3.push(h.rate);
        }
        Ok(out)
    })
}

/// `semwm._core`: the Rust engine's kernels (see docs/engines.md).
#[pymodule]
#[pyo3(name = "_core")]
fn semwm_core(module: &Bound<'_, PyModule>) -> PyResult<()> {
    module.add("__version__", env!("CARGO_PKG_VERSION"))?;
    module.add_class::<PyClassFilter>()?;
    module.add_function(wrap_pyfunction!(imm_mix, module)?)?;
    module.add_function(wrap_pyfunction!(predict, module)?)?;
    module.add_function(wrap_pyfunction!(update, module)?)?;
    module.add_function(wrap_pyfunction!(combine, module)?)?;
    module.add_function(wrap_pyfunction!(mahalanobis_squared, module)?)?;
    module.add_function(wrap_pyfunction!(survive, module)?)?;
    module.add_function(wrap_pyfunction!(missed, module)?)?;
    module.add_function(wrap_pyfunction!(inside_probability, module)?)?;
    module.add_function(wrap_pyfunction!(in_view_probability, module)?)?;
    module.add_function(wrap_pyfunction!(gauss_hermite_rule, module)?)?;
    module.add_function(wrap_pyfunction!(ndtr, module)?)?;
    module.add_function(wrap_pyfunction!(range_coverage, module)?)?;
    module.add_function(wrap_pyfunction!(hull_distance, module)?)?;
    module.add_class::<PyScanExpansion>()?;
    module.add_function(wrap_pyfunction!(merge_prune, module)?)?;
    module.add_function(wrap_pyfunction!(similar::merge_similar, module)?)?;
    module.add_class::<crate::python::rates::PyObservedRates>()?;
    module.add_class::<engine::PyEngine>()?;
    module.add_class::<engine::PyState>()?;
    module.add_class::<engine::PyBook>()?;
    module.add_class::<engine::PyVersionRef>()?;
    module.add_class::<published::PyPublished>()?;
    module.add_class::<reader::PyDetectionReader>()?;
    module.add_class::<scan::PyScan>()?;
    Ok(())
}
