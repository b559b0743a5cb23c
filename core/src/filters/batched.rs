//! Batched Kalman and IMM steps, as `semwm/filters/batched.py`: one object at a time
//! here, called over a batch by `crate::filters::factory` and the bindings.
//!
//! A Kalman filter is an IMM with one mode. Layout of one object (row-major):
//! `x` `M x n` mode-matched means, `p` `M x n x n` covariances, `mu` `M` mode
//! probabilities; `z` `d`, `r` `d x d`. The measurement matrix is `H = [I_d 0]`.
//!
//! Each kernel's body is generic over the object's [`Shape`] (`crate::filters::shape`):
//! the public function takes the sizes at run time and calls the body for its shape.
//!
//! IMM convention: `T[i, j] = P(mode j at k | mode i at k-1)`, rows sum to 1.
//! References: Bar-Shalom, Li, Kirubarajan, *Estimation with Applications to Tracking
//! and Navigation*, Section 11.6.6 (IMM).

use crate::error::KernelResult;
use crate::filters::shape::{with_shape, with_state, Shape};
use crate::filters::small::{inverse_and_log_det, quadratic_form, MAX_STATE};

const LOG_2PI: f64 = 1.8378770664093453; // log(2 pi)
/// The most modes an IMM may have here (scratch arrays are sized by it).
pub const MAX_MODES: usize = 8;

/// `out = a b` for `n x n` row-major matrices.
#[inline(always)]
fn matmul(a: &[f64], b: &[f64], n: usize, out: &mut [f64]) {
    for i in 0..n {
        for j in 0..n {
            let mut total = 0.0;
            for k in 0..n {
                total += a[i * n + k] * b[k * n + j];
            }
            out[i * n + j] = total;
        }
    }
}

/// `out = a b^T` for `n x n` row-major matrices.
#[inline(always)]
fn matmul_transposed(a: &[f64], b: &[f64], n: usize, out: &mut [f64]) {
    for i in 0..n {
        for j in 0..n {
            let mut total = 0.0;
            for k in 0..n {
                total += a[i * n + k] * b[j * n + k];
            }
            out[i * n + j] = total;
        }
    }
}

/// IMM interaction (mixing) of one object (`imm_mix` in Python):
///
/// ```text
/// cbar_j = sum_i T_ij mu_i,   omega_ij = T_ij mu_i / cbar_j,
/// x0_j = sum_i omega_ij x_i,  P0_j = sum_i omega_ij [P_i + (x_i - x0_j)(x_i - x0_j)^T]
/// ```
///
/// A mode nobody can reach (`cbar_j = 0`) starts from the mixture (`omega_ij = mu_i`).
/// Writes `x0`, `p0` and `cbar`. `t` is `M x M`.
#[allow(clippy::too_many_arguments)]
pub fn imm_mix(
    x: &[f64],
    p: &[f64],
    mu: &[f64],
    t: &[f64],
    m: usize,
    n: usize,
    x0: &mut [f64],
    p0: &mut [f64],
    cbar: &mut [f64],
) {
    if m == 1 {
        x0.copy_from_slice(x);
        p0.copy_from_slice(p);
        cbar.copy_from_slice(mu);
        return;
    }
    with_state!(n, |shape| mix_in(shape, x, p, mu, t, m, x0, p0, cbar))
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn mix_in<S: Shape>(
    shape: S,
    x: &[f64],
    p: &[f64],
    mu: &[f64],
    t: &[f64],
    m: usize,
    x0: &mut [f64],
    p0: &mut [f64],
    cbar: &mut [f64],
) {
    let n = shape.n();
    for j in 0..m {
        cbar[j] = (0..m).map(|i| mu[i] * t[i * m + j]).sum();
    }
    let mut omega = [0.0; MAX_MODES * MAX_MODES];
    for i in 0..m {
        for j in 0..m {
            omega[i * m + j] = if cbar[j] > 0.0 {
                t[i * m + j] * mu[i] / cbar[j]
            } else {
                mu[i]
            };
        }
    }
    let nn = n * n;
    for j in 0..m {
        for a in 0..n {
            x0[j * n + a] = (0..m).map(|i| omega[i * m + j] * x[i * n + a]).sum();
        }
        let mut spread = [0.0; MAX_STATE];
        let target = &mut p0[j * nn..(j + 1) * nn];
        target.fill(0.0);
        for i in 0..m {
            for a in 0..n {
                spread[a] = x[i * n + a] - x0[j * n + a];
            }
            let w = omega[i * m + j];
            for a in 0..n {
                for b in 0..n {
                    target[a * n + b] += w * (p[i * nn + a * n + b] + spread[a] * spread[b]);
                }
            }
        }
    }
}

/// Each mode's Kalman prediction from mixed states (`predict` in Python, after the
/// mixing): `x-_j = F_j x0_j`, `P-_j = F_j P0_j F_j^T + Q_j`. `f` and `q` are
/// `M x n x n`; results overwrite `x0` and `p0`.
pub fn predict_modes(x0: &mut [f64], p0: &mut [f64], f: &[f64], q: &[f64], m: usize, n: usize) {
    with_state!(n, |shape| predict_in(shape, x0, p0, f, q, m))
}

#[inline(always)]
fn predict_in<S: Shape>(shape: S, x0: &mut [f64], p0: &mut [f64], f: &[f64], q: &[f64], m: usize) {
    let n = shape.n();
    let nn = n * n;
    let mut fp = [0.0; MAX_STATE * MAX_STATE];
    let mut mean = [0.0; MAX_STATE];
    for j in 0..m {
        let fj = &f[j * nn..(j + 1) * nn];
        let xj = &mut x0[j * n..(j + 1) * n];
        for a in 0..n {
            mean[a] = (0..n).map(|b| fj[a * n + b] * xj[b]).sum();
        }
        xj.copy_from_slice(&mean[..n]);
        let pj = &mut p0[j * nn..(j + 1) * nn];
        matmul(fj, pj, n, &mut fp[..nn]);
        matmul_transposed(&fp[..nn], fj, n, pj);
        for (value, noise) in pj.iter_mut().zip(&q[j * nn..(j + 1) * nn]) {
            *value += noise;
        }
    }
}

/// IMM update of one object (`update` in Python): each mode's Kalman update in Joseph
/// form, then the mode probabilities.
///
/// ```text
/// y_j = z - H x_j,  S_j = H P_j H^T + R,  K_j = P_j H^T S_j^-1
/// x+_j = x_j + K_j y_j,  P+_j = (I - K_j H) P_j (I - K_j H)^T + K_j R K_j^T
/// Lambda_j = N(y_j; 0, S_j),  mu+_j = mu_j Lambda_j / sum_i mu_i Lambda_i
/// ```
///
/// Overwrites `x`, `p`, `mu`; returns `log sum_j mu_j Lambda_j`, the measurement's log
/// density under the predicted mixture. Errors when an `S_j` is not positive definite.
#[allow(clippy::too_many_arguments)]
pub fn update(
    x: &mut [f64],
    p: &mut [f64],
    mu: &mut [f64],
    z: &[f64],
    r: &[f64],
    m: usize,
    n: usize,
    d: usize,
) -> KernelResult<f64> {
    with_shape!(n, d, |shape| update_in(shape, x, p, mu, z, r, m))
}

#[inline(always)]
fn update_in<S: Shape>(
    shape: S,
    x: &mut [f64],
    p: &mut [f64],
    mu: &mut [f64],
    z: &[f64],
    r: &[f64],
    m: usize,
) -> KernelResult<f64> {
    let (n, d) = (shape.n(), shape.d());
    let nn = n * n;
    let mut log_lam = [0.0; MAX_MODES];
    let mut y = [0.0; 3];
    let mut s = [0.0; 9];
    let mut s_inv = [0.0; 9];
    let mut gain = [0.0; MAX_STATE * 3];
    let mut ikh = [0.0; MAX_STATE * MAX_STATE];
    let mut work = [0.0; MAX_STATE * MAX_STATE];
    let mut kr = [0.0; MAX_STATE * 3];
    for j in 0..m {
        let xj = &mut x[j * n..(j + 1) * n];
        let pj = &mut p[j * nn..(j + 1) * nn];
        for a in 0..d {
            y[a] = z[a] - xj[a];
            for b in 0..d {
                s[a * d + b] = pj[a * n + b] + r[a * d + b];
            }
        }
        let log_det = inverse_and_log_det(&s[..d * d], d, &mut s_inv[..d * d])?;
        // K = P H^T S^-1  (n x d)
        for a in 0..n {
            for b in 0..d {
                gain[a * d + b] = (0..d).map(|c| pj[a * n + c] * s_inv[c * d + b]).sum();
            }
        }
        for a in 0..n {
            xj[a] += (0..d).map(|b| gain[a * d + b] * y[b]).sum::<f64>();
        }
        // I - K H
        for a in 0..n {
            for b in 0..n {
                let identity = if a == b { 1.0 } else { 0.0 };
                ikh[a * n + b] = if b < d {
                    identity - gain[a * d + b]
                } else {
                    identity
                };
            }
        }
        matmul(&ikh[..nn], pj, n, &mut work[..nn]);
        matmul_transposed(&work[..nn], &ikh[..nn], n, pj);
        // + K R K^T
        for a in 0..n {
            for b in 0..d {
                kr[a * d + b] = (0..d).map(|c| gain[a * d + c] * r[c * d + b]).sum();
            }
        }
        for a in 0..n {
            for b in 0..n {
                pj[a * n + b] += (0..d).map(|c| kr[a * d + c] * gain[b * d + c]).sum::<f64>();
            }
        }
        log_lam[j] =
            -0.5 * (quadratic_form(&y[..d], &s_inv[..d * d], d) + log_det + d as f64 * LOG_2PI);
    }
    if m == 1 {
        mu[0] = 1.0;
        return Ok(log_lam[0]);
    }
    let mut top = f64::NEG_INFINITY;
    for j in 0..m {
        log_lam[j] += mu[j].max(1e-300).ln();
        top = top.max(log_lam[j]);
    }
    let total: f64 = (0..m).map(|j| (log_lam[j] - top).exp()).sum();
    let log_total = top + total.ln();
    for j in 0..m {
        mu[j] = (log_lam[j] - log_total).exp();
    }
    Ok(log_total)
}

/// The IMM's combined estimate of one object (`combine` in Python), moment matched:
/// `x^ = sum_j mu_j x_j`, `P^ = sum_j mu_j [P_j + (x_j - x^)(x_j - x^)^T]`.
pub fn combine(
    x: &[f64],
    p: &[f64],
    mu: &[f64],
    m: usize,
    n: usize,
    x_hat: &mut [f64],
    p_hat: &mut [f64],
) {
    let nn = n * n;
    if m == 1 {
        x_hat.copy_from_slice(&x[..n]);
        p_hat.copy_from_slice(&p[..nn]);
        return;
    }
    with_state!(n, |shape| combine_in(
        shape,
        x,
        p,
        mu,
        m,
        shape.n(),
        x_hat,
        p_hat
    ))
}

/// [`combine`]'s mean `x^` (`n`) and the leading `block x block` part of its `P^`
/// (`block`: `n` for the whole, `d` for the position's covariance; a constant of the
/// shape either way).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn combine_in<S: Shape>(
    shape: S,
    x: &[f64],
    p: &[f64],
    mu: &[f64],
    m: usize,
    block: usize,
    x_hat: &mut [f64],
    p_out: &mut [f64],
) {
    let n = shape.n();
    for a in 0..n {
        x_hat[a] = (0..m).map(|j| mu[j] * x[j * n + a]).sum();
    }
    for a in 0..block {
        for b in 0..block {
            p_out[a * block + b] = combined_entry(x, p, mu, m, n, x_hat, a, b);
        }
    }
}

/// Entry `(a, b)` of [`combine`]'s `P^` (`x_hat` the combined mean).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn combined_entry(
    x: &[f64],
    p: &[f64],
    mu: &[f64],
    m: usize,
    n: usize,
    x_hat: &[f64],
    a: usize,
    b: usize,
) -> f64 {
    let nn = n * n;
    let weighted: f64 = (0..m).map(|j| mu[j] * p[j * nn + a * n + b]).sum();
    let spread: f64 = (0..m)
        .map(|j| mu[j] * (x[j * n + a] - x_hat[a]) * (x[j * n + b] - x_hat[b]))
        .sum();
    weighted + spread
}

/// [`combine`]'s mean `x^` (`n`) and the leading `d x d` block of its `P^` (the
/// position's covariance), the same values entry by entry, without the rest of `P^`.
pub fn combine_position(
    x: &[f64],
    p: &[f64],
    mu: &[f64],
    (m, n, d): (usize, usize, usize),
    x_hat: &mut [f64],
    p_block: &mut [f64],
) {
    if m == 1 {
        x_hat.copy_from_slice(&x[..n]);
        for a in 0..d {
            p_block[a * d..(a + 1) * d].copy_from_slice(&p[a * n..a * n + d]);
        }
        return;
    }
    with_shape!(n, d, |shape| {
        combine_in(shape, x, p, mu, m, shape.d(), x_hat, p_block)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filters::shape::{Fixed, Runtime};

    /// Arbitrary values, and a covariance that is positive definite (`A A^T + I`).
    fn value(k: usize) -> f64 {
        ((k * 7919 % 1009) as f64 - 500.0) / 97.0
    }

    fn covariance(n: usize, seed: usize) -> Vec<f64> {
        let a: Vec<f64> = (0..n * n).map(|k| value(k + seed) / 5.0).collect();
        let mut c = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                c[i * n + j] = (0..n).map(|k| a[i * n + k] * a[j * n + k]).sum::<f64>()
                    + if i == j { 1.0 } else { 0.0 };
            }
        }
        c
    }

    fn bits(values: &[f64]) -> Vec<u64> {
        values.iter().map(|v| v.to_bits()).collect()
    }

    /// Every kernel with the shape fixed at compile time and with it at run time: the
    /// same bits (the module `shape`'s promise), for each shape the factory makes.
    fn fixed_equals_runtime<const N: usize, const D: usize>(m: usize) {
        let (n, d, nn) = (N, D, N * N);
        let x: Vec<f64> = (0..m * n).map(value).collect();
        let p: Vec<f64> = (0..m).flat_map(|j| covariance(n, 3 * j + 1)).collect();
        let total: f64 = (0..m).map(|j| 1.0 + j as f64).sum();
        let mu: Vec<f64> = (0..m).map(|j| (1.0 + j as f64) / total).collect();
        let t: Vec<f64> = (0..m * m)
            .map(|k| {
                if k / m == k % m {
                    0.9
                } else {
                    0.1 / (m.max(2) - 1) as f64
                }
            })
            .collect();
        let f: Vec<f64> = (0..m * nn).map(|k| value(k + 17) / 50.0).collect();
        let q: Vec<f64> = (0..m).flat_map(|j| covariance(n, 5 * j + 2)).collect();
        let z: Vec<f64> = (0..d).map(|k| value(k + 40)).collect();
        let r = covariance(d, 9);
        let (fixed, runtime) = (Fixed::<N, D>, Runtime { n, d });

        let (mut x0a, mut p0a, mut ca) = (vec![0.0; m * n], vec![0.0; m * nn], vec![0.0; m]);
        let (mut x0b, mut p0b, mut cb) = (x0a.clone(), p0a.clone(), ca.clone());
        mix_in(fixed, &x, &p, &mu, &t, m, &mut x0a, &mut p0a, &mut ca);
        mix_in(runtime, &x, &p, &mu, &t, m, &mut x0b, &mut p0b, &mut cb);
        assert_eq!(
            (bits(&x0a), bits(&p0a), bits(&ca)),
            (bits(&x0b), bits(&p0b), bits(&cb))
        );

        let (mut xa, mut pa, mut xb, mut pb) = (x.clone(), p.clone(), x.clone(), p.clone());
        predict_in(fixed, &mut xa, &mut pa, &f, &q, m);
        predict_in(runtime, &mut xb, &mut pb, &f, &q, m);
        assert_eq!((bits(&xa), bits(&pa)), (bits(&xb), bits(&pb)));

        if d > 0 {
            let (mut xa, mut pa, mut mua) = (x.clone(), p.clone(), mu.clone());
            let (mut xb, mut pb, mut mub) = (x.clone(), p.clone(), mu.clone());
            let la = update_in(fixed, &mut xa, &mut pa, &mut mua, &z, &r, m).unwrap();
            let lb = update_in(runtime, &mut xb, &mut pb, &mut mub, &z, &r, m).unwrap();
            assert_eq!(la.to_bits(), lb.to_bits());
            assert_eq!(
                (bits(&xa), bits(&pa), bits(&mua)),
                (bits(&xb), bits(&pb), bits(&mub))
            );

            let (mut ma, mut ba) = (vec![0.0; n], vec![0.0; d * d]);
            let (mut mb, mut bb) = (vec![0.0; n], vec![0.0; d * d]);
            combine_in(fixed, &x, &p, &mu, m, d, &mut ma, &mut ba);
            combine_in(runtime, &x, &p, &mu, m, d, &mut mb, &mut bb);
            assert_eq!((bits(&ma), bits(&ba)), (bits(&mb), bits(&bb)));
        }

        let (mut ma, mut fa) = (vec![0.0; n], vec![0.0; nn]);
        let (mut mb, mut fb) = (vec![0.0; n], vec![0.0; nn]);
        combine_in(fixed, &x, &p, &mu, m, n, &mut ma, &mut fa);
        combine_in(runtime, &x, &p, &mu, m, n, &mut mb, &mut fb);
        assert_eq!((bits(&ma), bits(&fa)), (bits(&mb), bits(&fb)));
    }

    #[test]
    fn kernels_of_a_fixed_shape_give_the_runtime_shapes_bits() {
        for m in [1, 2, 3] {
            fixed_equals_runtime::<1, 1>(m);
            fixed_equals_runtime::<2, 1>(m);
            fixed_equals_runtime::<2, 2>(m);
            fixed_equals_runtime::<4, 2>(m);
            fixed_equals_runtime::<3, 3>(m);
            fixed_equals_runtime::<6, 3>(m);
            fixed_equals_runtime::<4, 0>(m);
        }
    }

    #[test]
    fn combine_position_gives_combines_leading_block_bit_for_bit() {
        // modes of a 2-D constant-velocity IMM and a 3-D one, arbitrary values
        for (m, n, d) in [(1, 4, 2), (2, 4, 2), (3, 6, 3), (2, 2, 2)] {
            let value = |k: usize| ((k * 7919 % 1009) as f64 - 500.0) / 97.0;
            let x: Vec<f64> = (0..m * n).map(value).collect();
            let p: Vec<f64> = (0..m * n * n).map(|k| value(k + 31)).collect();
            let total: f64 = (0..m).map(|j| 1.0 + j as f64).sum();
            let mu: Vec<f64> = (0..m).map(|j| (1.0 + j as f64) / total).collect();
            let (mut mean, mut full) = (vec![0.0; n], vec![0.0; n * n]);
            combine(&x, &p, &mu, m, n, &mut mean, &mut full);
            let (mut position_mean, mut block) = (vec![0.0; n], vec![0.0; d * d]);
            combine_position(&x, &p, &mu, (m, n, d), &mut position_mean, &mut block);
            assert_eq!(position_mean, mean);
            for a in 0..d {
                for b in 0..d {
                    assert_eq!(block[a * d + b].to_bits(), full[a * n + b].to_bits());
                }
            }
        }
    }

    #[test]
    fn one_dimensional_kalman_update_is_the_scalar_formula() {
        // x = 0, P = 4, z = 1, R = 1: K = 0.8, x+ = 0.8, P+ = 0.8
        let (mut x, mut p, mut mu) = ([0.0], [4.0], [1.0]);
        let log_lik = update(&mut x, &mut p, &mut mu, &[1.0], &[1.0], 1, 1, 1).unwrap();
        assert!((x[0] - 0.8).abs() < 1e-15 && (p[0] - 0.8).abs() < 1e-15);
        let expected = -0.5 * (1.0 / 5.0 + 5.0f64.ln() + LOG_2PI);
        assert!((log_lik - expected).abs() < 1e-15);
    }

    #[test]
    fn mixing_keeps_probabilities_summing_to_one_and_combined_mean() {
        let x = [0.0, 1.0, 2.0, -1.0]; // M = 2, n = 2
        let p = [1.0, 0.0, 0.0, 1.0, 2.0, 0.1, 0.1, 3.0];
        let mu = [0.3, 0.7];
        let t = [0.9, 0.1, 0.2, 0.8];
        let (mut x0, mut p0, mut cbar) = ([0.0; 4], [0.0; 8], [0.0; 2]);
        imm_mix(&x, &p, &mu, &t, 2, 2, &mut x0, &mut p0, &mut cbar);
        assert!((cbar[0] + cbar[1] - 1.0).abs() < 1e-15);
        // the mixture's mean is kept: sum_j cbar_j x0_j = sum_i mu_i x_i
        for a in 0..2 {
            let before = mu[0] * x[a] + mu[1] * x[2 + a];
            let after = cbar[0] * x0[a] + cbar[1] * x0[2 + a];
            assert!((before - after).abs() < 1e-14);
        }
    }

    #[test]
    fn update_of_a_covariance_that_is_not_positive_definite_is_an_error() {
        let (mut x, mut p, mut mu) = ([0.0, 0.0], [-5.0, 0.0, 0.0, 1.0], [1.0]);
        let r = [1.0, 0.0, 0.0, 1.0];
        assert!(update(&mut x, &mut p, &mut mu, &[0.0, 0.0], &r, 1, 2, 2).is_err());
    }
}
