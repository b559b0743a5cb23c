//! Motion models, as `semwm/filters/motion.py` and `ClassFilter.models` /
//! `ClassFilter.transitions` in `semwm/filters/factory.py`.
//!
//! State layout: position first, then velocity, `x = [p_1..p_d, v_1..v_d]`. The Python
//! factory hands over each mode's polynomial coefficients once per class:
//!
//! ```text
//! F(dt) = F0 + dt F1,    Q(dt) = C0 + dt (C1 + dt (C2 + dt C3))
//! ```
//!
//! (zeroth order: `F = I`, `Q = dt Qc`; first order, white-noise acceleration:
//! `F = [[I, dt I], [0, I]]`, `Q = [[dt^3/3 Qc, dt^2/2 Qc], [dt^2/2 Qc, dt Qc]]`;
//! zeroth order inside an IMM: `F = [[I, 0], [0, 0]]`, `Q = [[dt Qc, 0], [0, sv^2 I]]`,
//! paper 002 IV-B).

/// Writes `F(dt)` and `Q(dt)` of one mode (`n x n` each) from its coefficients:
/// `f0`, `f1` (`n x n`) and `c` (`[C0, C1, C2, C3]`, each `n x n`).
pub fn models(f0: &[f64], f1: &[f64], c: [&[f64]; 4], dt: f64, f: &mut [f64], q: &mut [f64]) {
    for k in 0..f.len() {
        f[k] = f0[k] + dt * f1[k];
        q[k] = c[0][k] + dt * (c[1][k] + dt * (c[2][k] + dt * c[3][k]));
    }
}

/// Position gain `g` and velocity factor `k` of a speed `s` that decays at `alpha`
/// (m/s^2) over `dt`, integrated exactly (paper 004 IV-B; `decay_factors` in Python):
///
/// ```text
/// tau = min(dt, s / alpha),  g = tau - alpha tau^2 / (2 s),  k = max(0, s - alpha dt) / s
/// ```
///
/// `s = 0` gives `g = k = 0` (it stays put); `alpha <= 0`: `g = dt`, `k = 1`.
pub fn decay_factors(speed: f64, dt: f64, alpha: f64) -> (f64, f64) {
    if alpha <= 0.0 {
        return (dt, 1.0);
    }
    if speed > 0.0 {
        let tau = dt.min(speed / alpha);
        let g = tau - alpha * (tau * tau) / (2.0 * speed);
        let k = (speed - alpha * dt).max(0.0) / speed;
        (g, k)
    } else {
        (0.0, 0.0)
    }
}

/// The mode transition over a step `dt` with a period (`ClassFilter.transitions`):
///
/// ```text
/// T(dt) = T^(dt / period) = V diag(lam^(dt / period)) V^-1
/// ```
///
/// clipped to `[0, 1]` and each row divided by its sum. `lam`, `v`, `v_inv` are the
/// eigen-decomposition the Python factory computed once per class (`M`, `M x M`,
/// `M x M`); the result goes to `out` (`M x M`, `out[i, j] = P(mode j | mode i)`).
pub fn transition_power(lam: &[f64], v: &[f64], v_inv: &[f64], steps: f64, out: &mut [f64]) {
    let m = lam.len();
    let mut powers = [0.0; 8];
    for k in 0..m {
        powers[k] = lam[k].powf(steps);
    }
    for i in 0..m {
        for j in 0..m {
            let mut total = 0.0;
            for k in 0..m {
                total += v[i * m + k] * powers[k] * v_inv[k * m + j];
            }
            out[i * m + j] = total.clamp(0.0, 1.0);
        }
        let row: f64 = out[i * m..(i + 1) * m].iter().sum();
        for value in &mut out[i * m..(i + 1) * m] {
            *value /= row;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_order_models_are_the_textbook_ones() {
        // d = 1, first order: F0 = I, F1 = [[0, 1], [0, 0]]; C3 = Qc/3, C2 = Qc/2 off the
        // diagonal, C1 = Qc on the velocity
        let qc = 0.6;
        let f0 = [1.0, 0.0, 0.0, 1.0];
        let f1 = [0.0, 1.0, 0.0, 0.0];
        let zero = [0.0; 4];
        let c1 = [0.0, 0.0, 0.0, qc];
        let c2 = [0.0, qc / 2.0, qc / 2.0, 0.0];
        let c3 = [qc / 3.0, 0.0, 0.0, 0.0];
        let (mut f, mut q) = ([0.0; 4], [0.0; 4]);
        let dt = 0.5;
        models(&f0, &f1, [&zero, &c1, &c2, &c3], dt, &mut f, &mut q);
        assert_eq!(f, [1.0, dt, 0.0, 1.0]);
        let expected = [
            dt.powi(3) / 3.0 * qc,
            dt * dt / 2.0 * qc,
            dt * dt / 2.0 * qc,
            dt * qc,
        ];
        for (a, b) in q.iter().zip(expected) {
            assert!((a - b).abs() < 1e-15);
        }
    }

    #[test]
    fn decay_stops_the_object_and_integrates_exactly() {
        // 1 m/s decaying at 2 m/s^2 stops after 0.5 s, having moved 0.25 m
        let (g, k) = decay_factors(1.0, 2.0, 2.0);
        assert!((g * 1.0 - 0.25).abs() < 1e-15 && k == 0.0);
        // split into two steps: the same place
        let (g1, k1) = decay_factors(1.0, 0.2, 2.0);
        let (g2, _) = decay_factors(k1 * 1.0, 1.8, 2.0);
        assert!((g1 + g2 * k1 - 0.25).abs() < 1e-15);
        assert_eq!(decay_factors(0.0, 1.0, 2.0), (0.0, 0.0));
        assert_eq!(decay_factors(3.0, 1.5, 0.0), (1.5, 1.0));
    }

    #[test]
    fn transition_power_of_one_period_is_the_matrix_and_rows_sum_to_one() {
        // T = [[0.9, 0.1], [0.2, 0.8]]: lam = 1, 0.7; V = [[1, 1], [1, -2]]
        let lam = [1.0, 0.7];
        let v = [1.0, 1.0, 1.0, -2.0];
        let v_inv = [2.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0, -1.0 / 3.0];
        let mut out = [0.0; 4];
        transition_power(&lam, &v, &v_inv, 1.0, &mut out);
        for (a, b) in out.iter().zip([0.9, 0.1, 0.2, 0.8]) {
            assert!((a - b).abs() < 1e-15);
        }
        transition_power(&lam, &v, &v_inv, 0.37, &mut out);
        assert!((out[0] + out[1] - 1.0).abs() < 1e-15 && (out[2] + out[3] - 1.0).abs() < 1e-15);
    }
}
