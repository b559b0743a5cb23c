//! Small symmetric matrices of tracking (`d <= 3`), as `semwm/filters/small.py`.
//!
//! Row-major `d x d` slices. For `d = 2` the closed forms of the Python module:
//!
//! ```text
//! S = [[a, b], [b, c]],  |S| = ac - b^2,  S^-1 = [[c, -b], [-b, a]] / |S|
//! ```
//!
//! For other sizes a Cholesky factorisation checks positive definiteness (as
//! `numpy.linalg.cholesky` does in the Python engine) and LU with partial pivoting gives
//! the inverse and the solve (as LAPACK's `gesv` behind `numpy.linalg.inv`/`solve`).

use crate::error::{KernelError, KernelResult};

/// `S^-1` (written into `inverse`) and `log |S|` of a symmetric positive definite `S`.
///
/// Mirrors `semwm.filters.small.inverse_and_log_det` for one matrix. Errors with
/// `NotPositiveDefinite` when `S` is not.
#[inline]
pub fn inverse_and_log_det(s: &[f64], d: usize, inverse: &mut [f64]) -> KernelResult<f64> {
    if d == 2 {
        let (a, b, c) = (s[0], s[1], s[3]);
        let det = a * c - b * b;
        if det > 0.0 && a > 0.0 {
            inverse[0] = c / det;
            inverse[3] = a / det;
            let off = -b / det;
            inverse[1] = off;
            inverse[2] = off;
            return Ok(det.ln());
        }
    } else if d == 1 && s[0] > 0.0 {
        inverse[0] = 1.0 / s[0];
        return Ok(s[0].ln());
    }
    let mut factor = [0.0; 36];
    let log_det = cholesky_log_det(s, d, &mut factor[..d * d])?;
    lu_inverse(s, d, inverse)?;
    Ok(log_det)
}

/// `log |S|` from the Cholesky factor `S = L L^T` (written into `lower`); errors when
/// `S` is not positive definite.
pub fn cholesky_log_det(s: &[f64], d: usize, lower: &mut [f64]) -> KernelResult<f64> {
    lower.fill(0.0);
    let mut log_det = 0.0;
    for j in 0..d {
        let mut diagonal = s[j * d + j];
        for k in 0..j {
            diagonal -= lower[j * d + k] * lower[j * d + k];
        }
        if diagonal.is_nan() || diagonal <= 0.0 {
            return Err(KernelError::NotPositiveDefinite(format!(
                "Matrix is not positive definite (leading minor {} of a {d}x{d} matrix)",
                j + 1
            )));
        }
        let root = diagonal.sqrt();
        lower[j * d + j] = root;
        log_det += 2.0 * root.ln();
        for i in j + 1..d {
            let mut value = s[i * d + j];
            for k in 0..j {
                value -= lower[i * d + k] * lower[j * d + k];
            }
            lower[i * d + j] = value / root;
        }
    }
    Ok(log_det)
}

/// LU factorisation with partial pivoting of `a` (`d x d`, overwritten) with its row
/// permutation; errors on an exactly singular matrix.
fn lu_factor(a: &mut [f64], d: usize, pivot: &mut [usize]) -> KernelResult<()> {
    for (i, p) in pivot.iter_mut().enumerate() {
        *p = i;
    }
    for k in 0..d {
        let mut best = k;
        for i in k + 1..d {
            if a[i * d + k].abs() > a[best * d + k].abs() {
                best = i;
            }
        }
        if a[best * d + k] == 0.0 {
            return Err(KernelError::Singular("Singular matrix".to_string()));
        }
        if best != k {
            for j in 0..d {
                a.swap(k * d + j, best * d + j);
            }
            pivot.swap(k, best);
        }
        for i in k + 1..d {
            let factor = a[i * d + k] / a[k * d + k];
            a[i * d + k] = factor;
            for j in k + 1..d {
                a[i * d + j] -= factor * a[k * d + j];
            }
        }
    }
    Ok(())
}

/// The sign and `log |det A|` of a `d x d` matrix (`numpy.linalg.slogdet`), from an LU
/// factorisation with partial pivoting: `(0, -inf)` for a singular one.
pub fn slogdet(a: &[f64], d: usize) -> (f64, f64) {
    let mut lu = [0.0; 36];
    lu[..d * d].copy_from_slice(&a[..d * d]);
    let mut pivot = [0usize; 6];
    if lu_factor(&mut lu[..d * d], d, &mut pivot[..d]).is_err() {
        return (0.0, f64::NEG_INFINITY);
    }
    let mut sign = 1.0;
    let mut log_det = 0.0;
    for i in 0..d {
        let u = lu[i * d + i];
        if u < 0.0 {
            sign = -sign;
        }
        log_det += u.abs().ln();
    }
    // the permutation's parity
    let mut seen = [false; 6];
    for start in 0..d {
        if seen[start] {
            continue;
        }
        let mut length = 0;
        let mut at = start;
        while !seen[at] {
            seen[at] = true;
            at = pivot[at];
            length += 1;
        }
        if length % 2 == 0 {
            sign = -sign;
        }
    }
    (sign, log_det)
}

/// Solve `A x = b` in place of `b` from an LU factorisation.
fn lu_solve(lu: &[f64], d: usize, pivot: &[usize], b: &mut [f64]) {
    let mut permuted = [0.0; 6];
    for i in 0..d {
        permuted[i] = b[pivot[i]];
    }
    for i in 0..d {
        for k in 0..i {
            permuted[i] -= lu[i * d + k] * permuted[k];
        }
    }
    for i in (0..d).rev() {
        for k in i + 1..d {
            permuted[i] -= lu[i * d + k] * permuted[k];
        }
        permuted[i] /= lu[i * d + i];
    }
    b[..d].copy_from_slice(&permuted[..d]);
}

/// `A^-1` of a `d x d` matrix (`d <= 6`) into `inverse`.
pub fn lu_inverse(a: &[f64], d: usize, inverse: &mut [f64]) -> KernelResult<()> {
    let mut lu = [0.0; 36];
    lu[..d * d].copy_from_slice(&a[..d * d]);
    let mut pivot = [0usize; 6];
    lu_factor(&mut lu[..d * d], d, &mut pivot[..d])?;
    let mut column = [0.0; 6];
    for j in 0..d {
        column[..d].fill(0.0);
        column[j] = 1.0;
        lu_solve(&lu[..d * d], d, &pivot[..d], &mut column[..d]);
        for i in 0..d {
            inverse[i * d + j] = column[i];
        }
    }
    Ok(())
}

/// `r^T C^-1 r` given the inverse `C^-1` (`quadratic_form` in the Python module).
#[inline]
pub fn quadratic_form(residual: &[f64], inverse: &[f64], d: usize) -> f64 {
    let mut total = 0.0;
    for i in 0..d {
        for j in 0..d {
            total += residual[i] * inverse[i * d + j] * residual[j];
        }
    }
    total
}

/// `r^T C^-1 r` for a residual `r` and covariance `C` (`mahalanobis_squared` in the
/// Python module): the closed form for `d = 2` (no definiteness check, as there), a
/// solve otherwise.
pub fn mahalanobis_squared(residual: &[f64], covariance: &[f64], d: usize) -> KernelResult<f64> {
    if d == 2 {
        let (a, b, c) = (covariance[0], covariance[1], covariance[3]);
        let (r0, r1) = (residual[0], residual[1]);
        return Ok((c * r0 * r0 - 2.0 * b * r0 * r1 + a * r1 * r1) / (a * c - b * b));
    }
    let mut lu = [0.0; 36];
    lu[..d * d].copy_from_slice(&covariance[..d * d]);
    let mut pivot = [0usize; 6];
    lu_factor(&mut lu[..d * d], d, &mut pivot[..d])?;
    let mut solved = [0.0; 6];
    solved[..d].copy_from_slice(&residual[..d]);
    lu_solve(&lu[..d * d], d, &pivot[..d], &mut solved[..d]);
    Ok((0..d).map(|i| residual[i] * solved[i]).sum())
}

/// The largest state size the kernels take (`2 d` with `d <= 3`).
pub const MAX_STATE: usize = 6;

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * (1.0 + a.abs().max(b.abs()))
    }

    #[test]
    fn inverse_of_2x2_and_3x3_times_matrix_is_identity() {
        for (s, d) in [
            (vec![2.0, 0.3, 0.3, 1.0], 2),
            (vec![4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0], 3),
            (vec![0.5], 1),
        ] {
            let mut inverse = vec![0.0; d * d];
            let log_det = inverse_and_log_det(&s, d, &mut inverse).unwrap();
            for i in 0..d {
                for j in 0..d {
                    let product: f64 = (0..d).map(|k| s[i * d + k] * inverse[k * d + j]).sum();
                    assert!(close(product, if i == j { 1.0 } else { 0.0 }));
                }
            }
            let mut lower = vec![0.0; d * d];
            assert!(close(log_det, cholesky_log_det(&s, d, &mut lower).unwrap()));
        }
        // det of the 2x2: 2 - 0.09
        let mut inverse = [0.0; 4];
        let log_det = inverse_and_log_det(&[2.0, 0.3, 0.3, 1.0], 2, &mut inverse).unwrap();
        assert!(close(log_det, (2.0f64 - 0.09).ln()));
    }

    #[test]
    fn not_positive_definite_is_an_error_not_a_panic() {
        let mut inverse = [0.0; 9];
        let s = [1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        assert!(matches!(
            inverse_and_log_det(&s, 3, &mut inverse),
            Err(KernelError::NotPositiveDefinite(_))
        ));
        let nan = [f64::NAN, 0.0, 0.0, 1.0];
        assert!(inverse_and_log_det(&nan, 2, &mut inverse[..4]).is_err());
        let singular = [1.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        assert!(matches!(
            mahalanobis_squared(&[1.0, 0.0, 0.0], &singular, 3),
            Err(KernelError::Singular(_))
        ));
    }

    #[test]
    fn mahalanobis_matches_the_quadratic_form_of_the_inverse() {
        let s = [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0];
        let r = [0.3, -1.2, 0.7];
        let mut inverse = [0.0; 9];
        inverse_and_log_det(&s, 3, &mut inverse).unwrap();
        let expected = quadratic_form(&r, &inverse, 3);
        assert!(close(mahalanobis_squared(&r, &s, 3).unwrap(), expected));
        let s2 = [2.0, 0.3, 0.3, 1.0];
        let mut inverse2 = [0.0; 4];
        inverse_and_log_det(&s2, 2, &mut inverse2).unwrap();
        let r2 = [0.5, -0.25];
        assert!(close(
            mahalanobis_squared(&r2, &s2, 2).unwrap(),
            quadratic_form(&r2, &inverse2, 2)
        ));
    }
}
