//! One class's filter, batched over objects, as `ClassFilter` in
//! `semwm/filters/factory.py`: the numeric tables the Python factory builds once per
//! class (knowledge and validation stay in Python) and the prediction that uses them.

use crate::error::{KernelError, KernelResult};
use crate::filters::batched::{imm_mix, predict_modes, MAX_MODES};
use crate::filters::motion::{decay_factors, models, transition_power};
use crate::filters::small::MAX_STATE;

/// The eigen-decomposition `T = V diag(lam) V^-1` and the period `T` is stated for.
#[derive(Debug, Clone)]
pub struct TransitionPeriod {
    pub period: f64,
    pub lam: Vec<f64>,
    pub v: Vec<f64>,
    pub v_inv: Vec<f64>,
}

/// The numeric tables of one class's filter (`M` modes, state size `n`, dimension `d`).
#[derive(Debug, Clone)]
pub struct ClassTables {
    pub dim: usize,
    pub modes: usize,
    pub state: usize,
    /// `M x n x n` each: `F(dt) = F0 + dt F1`.
    pub f0: Vec<f64>,
    pub f1: Vec<f64>,
    /// `4 x M x n x n`: `Q(dt) = C0 + dt (C1 + dt (C2 + dt C3))`.
    pub c: Vec<f64>,
    /// `M x M`, `T[i, j] = P(mode j at k | mode i at k-1)`.
    pub transition: Vec<f64>,
    pub period: Option<TransitionPeriod>,
    /// The passive decay rate alpha (m/s^2) of the velocity, 0 for none.
    pub velocity_decay: f64,
    /// Which modes are first order (their velocity decays).
    pub first_order: Vec<bool>,
}

/// Checks a length and names the table.
fn expect_len(name: &str, got: usize, expected: usize) -> KernelResult<()> {
    if got == expected {
        Ok(())
    } else {
        Err(KernelError::Shape(format!(
            "{name}: expected {expected} values, got {got}"
        )))
    }
}

impl ClassTables {
    /// Checks the tables' sizes against each other.
    pub fn validate(&self) -> KernelResult<()> {
        let (m, n, d) = (self.modes, self.state, self.dim);
        // the state is the position, or the position and the velocity
        if !(1..=3).contains(&d) || (n != d && n != 2 * d) || n > MAX_STATE {
            return Err(KernelError::Shape(format!(
                "dim and state size: expected 1 <= dim <= 3 and n = dim or 2 dim, got dim {d}, n {n}"
            )));
        }
        if !(1..=MAX_MODES).contains(&m) {
            return Err(KernelError::Shape(format!(
                "modes: expected 1 to {MAX_MODES}, got {m}"
            )));
        }
        expect_len("F0", self.f0.len(), m * n * n)?;
        expect_len("F1", self.f1.len(), m * n * n)?;
        expect_len("C", self.c.len(), 4 * m * n * n)?;
        expect_len("transition", self.transition.len(), m * m)?;
        expect_len("first_order", self.first_order.len(), m)?;
        if let Some(period) = &self.period {
            expect_len("lam", period.lam.len(), m)?;
            expect_len("V", period.v.len(), m * m)?;
            expect_len("V_inv", period.v_inv.len(), m * m)?;
        }
        Ok(())
    }

    /// `Some((C0, C1))` when the filter is one mode with `F(dt) = I` and
    /// `Q(dt) = C0 + dt C1` (a zeroth-order Kalman filter: `ClassFilter._random_walk`).
    fn random_walk(&self) -> Option<(&[f64], &[f64])> {
        let (n, nn) = (self.state, self.state * self.state);
        if self.modes != 1 {
            return None;
        }
        let identity = (0..nn).all(|k| self.f0[k] == if k % (n + 1) == 0 { 1.0 } else { 0.0 });
        let linear =
            self.f1.iter().all(|&v| v == 0.0) && self.c[2 * nn..].iter().all(|&v| v == 0.0);
        (identity && linear).then(|| (&self.c[..nn], &self.c[nn..2 * nn]))
    }

    /// `T(dt)` (`M x M`) into `out`: the matrix itself once per step, or its power over
    /// the period.
    fn transition_for(&self, dt: f64, out: &mut [f64]) {
        match &self.period {
            Some(p) if self.modes > 1 => {
                transition_power(&p.lam, &p.v, &p.v_inv, dt / p.period, out)
            }
            _ => out.copy_from_slice(&self.transition),
        }
    }

    /// `F(dt)`, `Q(dt)` of every mode (`M x n x n` each).
    fn mode_models(&self, dt: f64, f: &mut [f64], q: &mut [f64]) {
        let nn = self.state * self.state;
        let mnn = self.modes * nn;
        for j in 0..self.modes {
            let part = j * nn..(j + 1) * nn;
            let c = [
                &self.c[part.start..part.end],
                &self.c[mnn + part.start..mnn + part.end],
                &self.c[2 * mnn + part.start..2 * mnn + part.end],
                &self.c[3 * mnn + part.start..3 * mnn + part.end],
            ];
            let (fj, qj) = (&mut f[part.clone()], &mut q[part.clone()]);
            models(
                &self.f0[part.clone()],
                &self.f1[part.clone()],
                c,
                dt,
                fj,
                qj,
            );
        }
    }

    /// Predicts `count` objects by their own `dt` (s), in place (`ClassFilter.predict`):
    /// objects with `dt <= 0` (or NaN) are left as they are, no mode transition either.
    /// `x` is `count x M x n`, `p` `count x M x n x n`, `mu` `count x M`.
    pub fn predict(
        &self,
        x: &mut [f64],
        p: &mut [f64],
        mu: &mut [f64],
        dt: &[f64],
    ) -> KernelResult<()> {
        let (m, n) = (self.modes, self.state);
        let nn = n * n;
        let count = dt.len();
        expect_len("x", x.len(), count * m * n)?;
        expect_len("P", p.len(), count * m * nn)?;
        expect_len("mu", mu.len(), count * m)?;
        if let Some((c0, c1)) = self.random_walk() {
            // x- = x, P- = P + C0 + dt C1: the general equations with F = I
            for (i, &step) in dt.iter().enumerate() {
                if step > 0.0 {
                    for (k, value) in p[i * nn..(i + 1) * nn].iter_mut().enumerate() {
                        *value += c0[k] + step * c1[k];
                    }
                }
            }
            return Ok(());
        }
        let decaying = self.velocity_decay > 0.0 && n > self.dim;
        let mut t = [0.0; MAX_MODES * MAX_MODES];
        // F, F for the covariance, Q, the mixed means and covariances: one block
        let mut scratch = vec![0.0; 4 * m * nn + m * n];
        let (f, rest) = scratch.split_at_mut(m * nn);
        let (f_cov, rest) = rest.split_at_mut(m * nn);
        let (q, rest) = rest.split_at_mut(m * nn);
        let (p0, x0) = rest.split_at_mut(m * nn);
        let mut cbar = [0.0; MAX_MODES];
        // the step's transition and models, kept for the next row of the same step (the
        // rows a scan predicts mostly share a few steps); the decay rewrites F per row
        let mut made_for: Option<f64> = None;
        for (i, &step) in dt.iter().enumerate() {
            if step.is_nan() || step <= 0.0 {
                continue;
            }
            let xi = &mut x[i * m * n..(i + 1) * m * n];
            let pi = &mut p[i * m * nn..(i + 1) * m * nn];
            let mui = &mut mu[i * m..(i + 1) * m];
            if decaying || made_for != Some(step) {
                self.transition_for(step, &mut t[..m * m]);
                self.mode_models(step, f, q);
                made_for = Some(step);
            }
            imm_mix(xi, pi, mui, &t[..m * m], m, n, x0, p0, &mut cbar[..m]);
            if decaying {
                self.decay(step, x0, p0, f, f_cov);
                predict_decaying(x0, p0, f, f_cov, q, m, n);
            } else {
                predict_modes(x0, p0, f, q, m, n);
            }
            xi.copy_from_slice(x0);
            pi.copy_from_slice(p0);
            mui.copy_from_slice(&cbar[..m]);
        }
        Ok(())
    }

    /// The transition matrices of a passive object whose speed decays
    /// (`ClassFilter._predict_decaying`): in each first-order mode the mean moves by the
    /// exact decayed motion (`p + g v`, `k v`, paper 004 IV-B) and the covariance by the
    /// same map at the speed `sqrt(|v|^2 + tr P_vv)`. Rewrites `f` (the mean's map) and
    /// `f_cov` (the covariance's).
    fn decay(&self, dt: f64, x0: &[f64], p0: &[f64], f: &mut [f64], f_cov: &mut [f64]) {
        let (n, d) = (self.state, self.dim);
        let nn = n * n;
        f_cov.copy_from_slice(f);
        for j in 0..self.modes {
            if !self.first_order[j] {
                continue;
            }
            let v = &x0[j * n + d..j * n + 2 * d];
            let speed = v.iter().map(|value| value * value).sum::<f64>().sqrt();
            let trace: f64 = (d..2 * d).map(|a| p0[j * nn + a * n + a]).sum();
            let spread = (speed * speed + trace).sqrt();
            for (target, s) in [(&mut *f, speed), (&mut *f_cov, spread)] {
                let (g, k) = decay_factors(s, dt, self.velocity_decay);
                for a in 0..d {
                    for b in 0..d {
                        let identity = if a == b { 1.0 } else { 0.0 };
                        target[j * nn + a * n + d + b] = g * identity;
                        target[j * nn + (d + a) * n + d + b] = k * identity;
                    }
                }
            }
        }
    }
}

/// `x- = F_mean x0`, `P- = F_cov P0 F_cov^T + Q` per mode.
fn predict_decaying(
    x0: &mut [f64],
    p0: &mut [f64],
    f_mean: &[f64],
    f_cov: &[f64],
    q: &[f64],
    m: usize,
    n: usize,
) {
    let nn = n * n;
    let mut mean = [0.0; MAX_STATE];
    for j in 0..m {
        let fj = &f_mean[j * nn..(j + 1) * nn];
        for a in 0..n {
            mean[a] = (0..n).map(|b| fj[a * n + b] * x0[j * n + b]).sum();
        }
        x0[j * n..(j + 1) * n].copy_from_slice(&mean[..n]);
    }
    // the covariance part is the general prediction with F_cov; its mean is dropped
    let mut scratch = x0.to_vec();
    predict_modes(&mut scratch, p0, f_cov, q, m, n);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1-D constant-velocity Kalman filter: F = [[1, dt], [0, 1]].
    fn constant_velocity(qc: f64) -> ClassTables {
        ClassTables {
            dim: 1,
            modes: 1,
            state: 2,
            f0: vec![1.0, 0.0, 0.0, 1.0],
            f1: vec![0.0, 1.0, 0.0, 0.0],
            c: [
                vec![0.0; 4],
                vec![0.0, 0.0, 0.0, qc],
                vec![0.0, qc / 2.0, qc / 2.0, 0.0],
                vec![qc / 3.0, 0.0, 0.0, 0.0],
            ]
            .concat(),
            transition: vec![1.0],
            period: None,
            velocity_decay: 0.0,
            first_order: vec![true],
        }
    }

    #[test]
    fn constant_velocity_prediction_moves_by_v_dt_and_skips_dt_zero() {
        let tables = constant_velocity(0.0);
        tables.validate().unwrap();
        let mut x = vec![1.0, 2.0, 1.0, 2.0];
        let mut p = vec![1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0];
        let mut mu = vec![1.0, 1.0];
        tables
            .predict(&mut x, &mut p, &mut mu, &[0.5, 0.0])
            .unwrap();
        assert_eq!(&x, &[2.0, 2.0, 1.0, 2.0]);
        // F P F^T with P = I: [[1 + dt^2, dt], [dt, 1]]
        assert_eq!(&p[..4], &[1.25, 0.5, 0.5, 1.0]);
        assert_eq!(&p[4..], &[1.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn mismatched_tables_are_a_shape_error_naming_the_table() {
        let mut tables = constant_velocity(1.0);
        tables.f1.pop();
        let error = tables.validate().unwrap_err();
        assert_eq!(
            error,
            KernelError::Shape("F1: expected 4 values, got 3".to_string())
        );
        let mut odd = constant_velocity(1.0);
        odd.dim = 3; // n = 2 is neither dim nor 2 dim
        let error = odd.validate().unwrap_err();
        assert!(matches!(error, KernelError::Shape(m) if m.starts_with("dim and state size")));
        let tables = constant_velocity(1.0);
        let error = tables
            .predict(&mut [0.0; 3], &mut [0.0; 4], &mut [1.0], &[1.0])
            .unwrap_err();
        assert!(matches!(error, KernelError::Shape(message) if message.starts_with("x:")));
    }

    #[test]
    fn a_decaying_velocity_stops_the_mean() {
        let mut tables = constant_velocity(0.0);
        tables.velocity_decay = 2.0;
        let mut x = vec![0.0, 1.0];
        let mut p = vec![0.0; 4];
        let mut mu = vec![1.0];
        tables.predict(&mut x, &mut p, &mut mu, &[2.0]).unwrap();
        assert!((x[0] - 0.25).abs() < 1e-15 && x[1] == 0.0);
    }
}
