//! Existence of objects in continuous time and the missed-detection term: the kernels of
//! `semwm/mhf/existence.py` (the `mht` association model), which is their specification.
//!
//! Between detections an object that exists leaves at rate `mu` (Hz) or is detected at
//! rate `f` (Hz). Over `dt` seconds with no detection of it (`survive`):
//!
//! ```text
//! P(exists at t + dt, no detection) = r exp(-(mu + f) dt)
//! q  = (1 - r) + r (exp(-(mu + f) dt) + mu / (mu + f) (1 - exp(-(mu + f) dt)))
//! r' = r exp(-(mu + f) dt) / q
//! ```
//!
//! After a scan that could have reported the object with probability `p` and did not
//! (`missed`, the Bernoulli track's missed-detection update of PMBM):
//! `q = 1 - r p`, `r' = r (1 - p) / q`.
//!
//! `inside_probability`: the probability that a Gaussian position estimate lies in the
//! region (an axis-aligned box) widened by a margin per axis, per axis independently,
//! `prod_i Phi((b_i + m_i - x_i) / sigma_i) - Phi((a_i - m_i - x_i) / sigma_i)`.
//!
//! `in_view_probability`: the probability that the estimate's horizontal marginal lies
//! in a sensor's view (a disc sector), by a 7 x 7 Gauss-Hermite rule.
//!
//! Every kernel works on one object at a time; the bindings (`crate::python`) loop.

use crate::error::{KernelError, KernelResult};

/// `(r', log q)` after `dt` seconds with no detection, leave rate `mu` and detection
/// rate `f` (Hz): the module's first equations, in the order of `survive` in Python.
pub fn survive(r: f64, mu: f64, f: f64, dt: f64) -> (f64, f64) {
    let total = mu + f;
    let stay = (-total * dt).exp(); // P(still there and not detected | exists)
    let share = if total > 0.0 { mu / total } else { 0.0 };
    let left = share * (1.0 - stay);
    let q = ((1.0 - r) + r * (stay + left)).max(1e-300);
    let r_new = (r * stay / q).clamp(0.0, 1.0); // NaN stays NaN, as in numpy
    (r_new, q.ln())
}

/// `(r', log q)` after a scan that could have reported the object with probability `p`
/// and did not: `q = 1 - r p`, `r' = r (1 - p) / q` (`missed` in Python).
pub fn missed(r: f64, p: f64) -> (f64, f64) {
    let q = (1.0 - r * p).max(1e-300);
    let r_new = (r * (1.0 - p) / q).clamp(0.0, 1.0);
    (r_new, q.ln())
}

// ---------------------------------------------------------------- the normal CDF
// `ndtr`, `erf` and `erfc` as Cephes computes them (S. L. Moshier; the code scipy.special
// runs), so that the Rust engine's probabilities equal scipy's to rounding.

const SQRT1_2: f64 = std::f64::consts::FRAC_1_SQRT_2;
/// log(f64::MAX): below `-MAXLOG` `exp` underflows.
const MAXLOG: f64 = 7.097_827_128_933_84e2;

#[allow(clippy::excessive_precision)]
const ERFC_P: [f64; 9] = [
    2.461_969_814_735_305_125_24e-10,
    5.641_895_648_310_688_219_77e-1,
    7.463_210_564_422_699_126_87e0,
    4.863_719_709_856_813_666_14e1,
    1.965_208_329_560_770_982_42e2,
    5.264_451_949_954_773_586_31e2,
    9.345_285_271_719_576_075_40e2,
    1.027_551_886_895_157_102_72e3,
    5.575_353_353_693_993_275_26e2,
];
#[allow(clippy::excessive_precision)]
const ERFC_Q: [f64; 8] = [
    1.322_819_511_547_449_925_08e1,
    8.670_721_408_859_897_423_29e1,
    3.549_377_788_878_198_910_62e2,
    9.757_085_017_432_054_897_53e2,
    1.823_909_166_879_097_362_89e3,
    2.246_337_608_187_109_817_92e3,
    1.656_663_091_941_613_501_82e3,
    5.575_353_408_177_276_755_46e2,
];
#[allow(clippy::excessive_precision)]
const ERFC_R: [f64; 6] = [
    5.641_895_835_477_550_739_84e-1,
    1.275_366_707_599_781_044_16e0,
    5.019_050_422_511_804_774_14e0,
    6.160_210_979_930_535_851_95e0,
    7.409_742_699_504_489_391_60e0,
    2.978_866_653_721_002_406_70e0,
];
#[allow(clippy::excessive_precision)]
const ERFC_S: [f64; 6] = [
    2.260_528_632_201_172_765_90e0,
    9.396_035_249_380_014_346_73e0,
    1.204_895_398_080_966_566_05e1,
    1.708_144_507_475_658_972_22e1,
    9.608_968_090_632_858_781_98e0,
    3.369_076_451_000_815_160_50e0,
];
#[allow(clippy::excessive_precision)]
const ERF_T: [f64; 5] = [
    9.604_973_739_870_516_387_49e0,
    9.002_601_972_038_426_892_17e1,
    2.232_005_345_946_843_192_26e3,
    7.003_325_141_128_050_754_73e3,
    5.559_230_130_103_949_627_68e4,
];
#[allow(clippy::excessive_precision)]
const ERF_U: [f64; 5] = [
    3.356_171_416_475_030_996_47e1,
    5.213_579_497_801_526_797_95e2,
    4.594_323_829_709_801_279_87e3,
    2.262_900_006_138_909_342_46e4,
    4.926_739_426_086_359_210_86e4,
];

/// `c[0] x^k + c[1] x^(k-1) + ... + c[k]` (Horner).
fn polevl(x: f64, c: &[f64]) -> f64 {
    c[1..].iter().fold(c[0], |sum, &ci| sum * x + ci)
}

/// `x^k + c[0] x^(k-1) + ... + c[k-1]`: the leading coefficient 1 left out.
fn p1evl(x: f64, c: &[f64]) -> f64 {
    c[1..].iter().fold(x + c[0], |sum, &ci| sum * x + ci)
}

/// The error function (Cephes `erf`).
pub fn erf(x: f64) -> f64 {
    if x.is_nan() {
        return f64::NAN;
    }
    if x < 0.0 {
        return -erf(-x);
    }
    if x > 1.0 {
        return 1.0 - erfc(x);
    }
    let z = x * x;
    x * polevl(z, &ERF_T) / p1evl(z, &ERF_U)
}

/// The complementary error function (Cephes `erfc`).
pub fn erfc(a: f64) -> f64 {
    if a.is_nan() {
        return f64::NAN;
    }
    let x = a.abs();
    if x < 1.0 {
        return 1.0 - erf(a);
    }
    let z = -a * a;
    let under = if a < 0.0 { 2.0 } else { 0.0 };
    if z < -MAXLOG {
        return under;
    }
    let z = z.exp();
    let (p, q) = if x < 8.0 {
        (polevl(x, &ERFC_P), p1evl(x, &ERFC_Q))
    } else {
        (polevl(x, &ERFC_R), p1evl(x, &ERFC_S))
    };
    let mut y = (z * p) / q;
    if a < 0.0 {
        y = 2.0 - y;
    }
    if y == 0.0 {
        return under;
    }
    y
}

/// The standard normal CDF `Phi(a)` (Cephes `ndtr`, scipy.special.ndtr).
pub fn ndtr(a: f64) -> f64 {
    if a.is_nan() {
        return f64::NAN;
    }
    let x = a * SQRT1_2;
    let z = x.abs();
    if z < SQRT1_2 {
        0.5 + 0.5 * erf(x)
    } else {
        let y = 0.5 * erfc(z);
        if x > 0.0 {
            1.0 - y
        } else {
            y
        }
    }
}

// ---------------------------------------------------------------- region and view

/// The probability that one object (position `x` `(d,)`, covariance `p` `(d, d)`) lies
/// inside the box `[low - m, high + m]` (`m`: its margin per axis, or none):
/// `prod_i Phi((high_i + m_i - x_i) / sigma_i) - Phi((low_i - m_i - x_i) / sigma_i)`,
/// each axis's factor clipped to `[0, 1]`, `sigma_i = sqrt(max(P_ii, 1e-18))`.
pub fn inside_probability(
    x: &[f64],
    p: &[f64],
    low: &[f64],
    high: &[f64],
    margin: Option<&[f64]>,
) -> f64 {
    let d = x.len();
    let mut product = 1.0;
    for i in 0..d {
        let sigma = p[i * d + i].max(1e-18).sqrt();
        let (upper, lower) = match margin {
            Some(m) => (high[i] + m[i], low[i] + -m[i]),
            None => (high[i], low[i]),
        };
        let below_upper = ndtr((upper - x[i]) / sigma);
        let below_lower = ndtr((lower - x[i]) / sigma);
        let axis = (below_upper - below_lower).clamp(0.0, 1.0);
        product = if i == 0 { axis } else { product * axis };
    }
    product
}

/// The nodes of the 7-point Gauss-Hermite rule for a standard normal (probabilists'),
/// as `numpy.polynomial.hermite_e.hermegauss(7)` gives them.
#[allow(clippy::excessive_precision)]
pub const GH_X: [f64; 7] = [
    -3.750_439_717_725_742_5,
    -2.366_759_410_734_541,
    -1.154_405_394_739_968_2,
    0.0,
    1.154_405_394_739_968_2,
    2.366_759_410_734_541,
    3.750_439_717_725_742_5,
];
/// Its weights, normalised to sum to 1 (as `semwm.mhf.existence` normalises them).
#[allow(clippy::excessive_precision)]
pub const GH_W: [f64; 7] = [
    0.000_548_268_855_972_217,
    0.030_757_123_967_586_52,
    0.240_123_178_605_012_7,
    0.457_142_857_142_857_24,
    0.240_123_178_605_012_7,
    0.030_757_123_967_586_52,
    0.000_548_268_855_972_217,
];

/// A sensor's view: a disc sector of radius `range` (m) and opening `2 half_angle`
/// (rad) around `heading` (rad), seen from `position` (its first two entries).
#[derive(Debug, Clone, Copy)]
pub struct View {
    pub position: [f64; 2],
    pub heading: f64,
    pub range: Option<f64>,
    pub half_angle: Option<f64>,
}

/// `a mod b` with the sign of `b`, as numpy's `remainder` (Python's `%`) computes it.
fn remainder(a: f64, b: f64) -> f64 {
    let m = a % b; // fmod
    if m != 0.0 {
        if (b < 0.0) != (m < 0.0) {
            m + b
        } else {
            m
        }
    } else {
        0.0_f64.copysign(b)
    }
}

/// The sensor's heading as a unit vector and the cosine of its half angle, made once
/// per object for [`within_half_angle`].
struct Opening {
    hx: f64,
    hy: f64,
    half_angle: f64,
    cos_half: f64,
    sin_half: f64,
}

impl Opening {
    fn of(view: &View, half_angle: f64) -> Opening {
        Opening {
            hx: view.heading.cos(),
            hy: view.heading.sin(),
            half_angle,
            cos_half: half_angle.cos(),
            sin_half: half_angle.sin(),
        }
    }
}

/// Whether the point `(ox, oy)` from the sensor, `distance` from it, lies within the
/// sensor's half angle of its heading: the bearing's test of `in_view_probability`,
/// `|wrap(atan2(oy, ox) - heading)| <= half_angle`, answered without `atan2` where the
/// point is clearly on one side. The angle between the point and the heading is within
/// a half angle in `[0, pi)` exactly when `o . h >= |o| cos(half_angle)`; where the two
/// sides differ by more than `1e-9 |o|` (rounding moves either test by about
/// `1e-15 |o|`) both tests answer the same, and only points nearer the edge than that
/// (or at the sensor) take the bearing.
fn within_half_angle(ox: f64, oy: f64, distance: f64, view: &View, opening: &Opening) -> bool {
    let half_angle = opening.half_angle;
    if half_angle >= std::f64::consts::PI {
        return true; // |bearing| <= pi
    }
    if half_angle >= 0.0 {
        let gap = ox * opening.hx + oy * opening.hy - distance * opening.cos_half;
        let clear = 1e-9 * distance;
        if gap > clear {
            return true;
        }
        if gap < -clear {
            return false;
        }
    }
    half_angle - bearing(ox, oy, view).abs() >= 0.0
}

/// Whether the point `(ox, oy)`, `distance` from the sensor, lies within the sensor's
/// half angle of its heading and at least `m` (m) from the opening's nearer edge: the
/// eroded view's test of `in_view_probability`, `slack = half_angle - |bearing| >= 0`
/// and `distance sin(slack) >= m` (`distance` when `slack >= pi / 2`). With `o . h =
/// |o| cos(bearing)` and `|o x h| = |o| sin|bearing|` the distance to the edge is
/// `sin(half_angle) o . h - cos(half_angle) |o x h|` (the same identity, no `atan2`),
/// used where each test is clear by far more than rounding, as in
/// [`within_half_angle`]; otherwise the bearing decides.
fn clear_of_the_edge(
    ox: f64,
    oy: f64,
    distance: f64,
    view: &View,
    opening: &Opening,
    m: f64,
) -> bool {
    let half_angle = opening.half_angle;
    if (0.0..std::f64::consts::PI).contains(&half_angle) {
        let dot = ox * opening.hx + oy * opening.hy;
        let cross = (opening.hx * oy - opening.hy * ox).abs();
        let clear = 1e-9 * distance;
        let gap = dot - distance * opening.cos_half;
        if gap < -clear {
            return false; // outside the opening
        }
        if gap > clear {
            // cos(slack) <= 0: at a right angle or more from the nearer edge
            let to_edge = if opening.cos_half * dot + opening.sin_half * cross <= 0.0 {
                distance
            } else {
                opening.sin_half * dot - opening.cos_half * cross
            };
            let room = 1e-9 * (distance + m.abs());
            if to_edge - m > room {
                return true;
            }
            if to_edge - m < -room {
                return false;
            }
        }
    }
    let slack = half_angle - bearing(ox, oy, view).abs();
    let to_edge = if slack >= 0.5 * std::f64::consts::PI {
        distance
    } else {
        distance * slack.sin()
    };
    slack >= 0.0 && to_edge >= m
}

/// The bearing of `(ox, oy)` from the sensor's heading, wrapped to `[-pi, pi)`.
fn bearing(ox: f64, oy: f64, view: &View) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    remainder(oy.atan2(ox) - view.heading + std::f64::consts::PI, two_pi) - std::f64::consts::PI
}

/// The probability that one object lies in `view`, from the horizontal marginal of its
/// estimate (`x` `(d,)`, `p` `(d, d)`, `d >= 2`): the 7 x 7 Gauss-Hermite points
/// `x + L g` (`L` the Cholesky factor of `P[:2, :2] + 1e-12 I`), each weighted by
/// `GH_W[i] GH_W[j]` if it lies within `range` of the sensor and within `half_angle` of
/// its heading.
pub fn in_view_probability(
    x: &[f64],
    p: &[f64],
    d: usize,
    view: &View,
    margin: Option<f64>,
) -> KernelResult<f64> {
    in_view_sum(x, p, d, view, margin, None)
}

/// Whether `in_view_probability(x, p, d, view, None) >= level`, found with the points
/// summed in the same order but only as far as the answer needs: the partial sums of
/// weights only grow, so one at `level` or above answers yes; one that the points left
/// cannot lift to `level` (their weights' sum, with room for rounding) answers no.
pub fn in_view_reaches(
    x: &[f64],
    p: &[f64],
    d: usize,
    view: &View,
    level: f64,
) -> KernelResult<bool> {
    Ok(in_view_sum(x, p, d, view, None, Some(level))? >= level)
}

/// `in_view_probability`'s sum; with `level`, stopped once the sum is at `level` or
/// cannot reach it (see [`in_view_reaches`]).
fn in_view_sum(
    x: &[f64],
    p: &[f64],
    d: usize,
    view: &View,
    margin: Option<f64>,
    level: Option<f64>,
) -> KernelResult<f64> {
    let a00 = p[0] + 1e-12;
    let a10 = p[d];
    let a11 = p[d + 1] + 1e-12;
    if a00 <= 0.0 || a00.is_nan() {
        return Err(KernelError::NotPositiveDefinite(
            "Matrix is not positive definite".to_string(),
        ));
    }
    let l00 = a00.sqrt();
    let l10 = a10 / l00;
    let rest = a11 - l10 * l10;
    if rest <= 0.0 || rest.is_nan() {
        return Err(KernelError::NotPositiveDefinite(
            "Matrix is not positive definite".to_string(),
        ));
    }
    let l11 = rest.sqrt();
    if let Some(range) = view.range {
        // every point beyond the range, by far more than rounding: none counts
        let widest = GH_X[GH_X.len() - 1] * (l00 * l00 + (l10.abs() + l11).powi(2)).sqrt();
        let centre = (x[0] - view.position[0]).hypot(x[1] - view.position[1]);
        if centre - widest > range + 1e-9 * (1.0 + range.abs() + centre) {
            return Ok(0.0);
        }
    }
    let opening = view
        .half_angle
        .map(|half_angle| Opening::of(view, half_angle));
    let mut total = 0.0;
    for (i, &gi) in GH_X.iter().enumerate() {
        for (j, &gj) in GH_X.iter().enumerate() {
            let px = x[0] + (l00 * gi + 0.0 * gj);
            let py = x[1] + (l10 * gi + l11 * gj);
            let ox = px - view.position[0];
            let oy = py - view.position[1];
            let mut inside = true;
            let distance = (ox * ox + oy * oy).sqrt();
            let m = margin.unwrap_or(0.0);
            if let Some(range) = view.range {
                inside &= distance <= range - m;
            }
            if !inside {
                continue; // beyond the range: its bearing cannot bring it back
            }
            if let Some(opening) = &opening {
                inside = match margin {
                    None => within_half_angle(ox, oy, distance, view, opening),
                    Some(m) => clear_of_the_edge(ox, oy, distance, view, opening, m),
                };
            }
            if inside {
                total += GH_W[i] * GH_W[j];
                if level.is_some_and(|level| total >= level) {
                    return Ok(total);
                }
            }
        }
        if let Some(level) = level {
            let left: f64 = GH_W[i + 1..].iter().sum();
            if total + left < level - 1e-12 {
                return Ok(total);
            }
        }
    }
    Ok(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Uniform numbers in `[0, 1)` from `seed` (xorshift64): the tests' random cases.
    fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// `in_view_probability` as it was written first: every point's bearing by `atan2`,
    /// the reference the shortcuts must equal bit for bit.
    fn in_view_by_bearings(
        x: &[f64],
        p: &[f64],
        d: usize,
        view: &View,
        margin: Option<f64>,
    ) -> f64 {
        let l00 = (p[0] + 1e-12).sqrt();
        let l10 = p[d] / l00;
        let l11 = (p[d + 1] + 1e-12 - l10 * l10).sqrt();
        let two_pi = 2.0 * std::f64::consts::PI;
        let mut total = 0.0;
        for (i, &gi) in GH_X.iter().enumerate() {
            for (j, &gj) in GH_X.iter().enumerate() {
                let ox = x[0] + (l00 * gi + 0.0 * gj) - view.position[0];
                let oy = x[1] + (l10 * gi + l11 * gj) - view.position[1];
                let mut inside = true;
                let distance = (ox * ox + oy * oy).sqrt();
                let m = margin.unwrap_or(0.0);
                if let Some(range) = view.range {
                    inside &= distance <= range - m;
                }
                if let Some(half_angle) = view.half_angle {
                    let bearing = oy.atan2(ox) - view.heading;
                    let bearing =
                        remainder(bearing + std::f64::consts::PI, two_pi) - std::f64::consts::PI;
                    let slack = half_angle - bearing.abs();
                    inside &= slack >= 0.0;
                    if margin.is_some() {
                        let to_edge = if slack >= 0.5 * std::f64::consts::PI {
                            distance
                        } else {
                            distance * slack.sin()
                        };
                        inside &= to_edge >= m;
                    }
                }
                if inside {
                    total += GH_W[i] * GH_W[j];
                }
            }
        }
        total
    }

    #[test]
    fn in_view_equals_the_bearings_everywhere_and_at_the_edges() {
        // random views and estimates, many of them with a point on a view's edge (the
        // estimate's mean placed on it, a point variance of 0)
        let mut next = uniform(0x9E37_79B9_7F4A_7C15);
        let mut checked = 0;
        let mut partly = 0;
        for case in 0..20_000 {
            let heading = (next() - 0.5) * 20.0;
            let half_angle = match case % 5 {
                0 => None,
                1 => Some(std::f64::consts::PI + next()),
                _ => Some(next() * 3.2),
            };
            let view = View {
                position: [(next() - 0.5) * 10.0, (next() - 0.5) * 10.0],
                heading,
                range: if case % 7 == 0 {
                    None
                } else {
                    Some(next() * 8.0)
                },
                half_angle,
            };
            let on_edge = case % 3 == 0 && half_angle.is_some();
            let (r, angle) = (next() * 6.0, heading + half_angle.unwrap_or(0.0));
            let x = if on_edge {
                [
                    view.position[0] + r * angle.cos(),
                    view.position[1] + r * angle.sin(),
                ]
            } else {
                [
                    view.position[0] + (next() - 0.5) * 16.0,
                    view.position[1] + (next() - 0.5) * 16.0,
                ]
            };
            let spread = if on_edge && case % 2 == 0 {
                0.0
            } else {
                next() * 4.0
            };
            let c = (next() - 0.5) * spread;
            let p = [spread, c, c, spread + next()];
            for margin in [None, Some(next() * 0.5)] {
                let fast = in_view_probability(&x, &p, 2, &view, margin).unwrap();
                let slow = in_view_by_bearings(&x, &p, 2, &view, margin);
                assert_eq!(
                    fast.to_bits(),
                    slow.to_bits(),
                    "case {case}, margin {margin:?}"
                );
                checked += 1;
                partly += usize::from(fast > 0.0 && fast < 0.999);
            }
        }
        // an eroded view's edge: the mean `margin` from the opening's edge, inside it
        for case in 0..20_000 {
            let heading = (next() - 0.5) * 20.0;
            let half_angle = 0.05 + next() * 3.0;
            let margin = next() * 0.5;
            let view = View {
                position: [(next() - 0.5) * 10.0, (next() - 0.5) * 10.0],
                heading,
                range: Some(20.0),
                half_angle: Some(half_angle),
            };
            let r = margin + 0.01 + next() * 6.0;
            let side = if case % 2 == 0 { 1.0 } else { -1.0 };
            let angle = heading + side * (half_angle - (margin / r).asin());
            let x = [
                view.position[0] + r * angle.cos(),
                view.position[1] + r * angle.sin(),
            ];
            let spread = if case % 4 < 2 { 0.0 } else { next() * 0.01 };
            let p = [spread, 0.0, 0.0, spread];
            let fast = in_view_probability(&x, &p, 2, &view, Some(margin)).unwrap();
            let slow = in_view_by_bearings(&x, &p, 2, &view, Some(margin));
            assert_eq!(fast.to_bits(), slow.to_bits(), "edge case {case}");
            checked += 1;
        }
        assert_eq!(checked, 60_000);
        assert!(partly > 2_000, "{partly} estimates across an edge");
    }

    #[test]
    fn in_view_reaches_answers_as_the_whole_sum_compares() {
        let mut next = uniform(0x2545_F491_4F6C_DD1D);
        let (mut yes, mut no) = (0, 0);
        for case in 0..20_000 {
            let view = View {
                position: [0.0, 0.0],
                heading: (next() - 0.5) * 7.0,
                range: Some(1.0 + next() * 6.0),
                half_angle: Some(0.2 + next() * 1.5),
            };
            let x = [(next() - 0.5) * 14.0, (next() - 0.5) * 14.0];
            let spread = next() * 3.0;
            let c = (next() - 0.5) * spread;
            let p = [spread, c, c, spread + next()];
            let whole = in_view_probability(&x, &p, 2, &view, None).unwrap();
            // levels at the whole sum and next to it, as well as the usual half
            let levels = [0.5, whole, f64::from_bits(whole.to_bits() + 1), next()];
            for level in levels {
                let reached = in_view_reaches(&x, &p, 2, &view, level).unwrap();
                assert_eq!(reached, whole >= level, "case {case}, level {level}");
                if reached {
                    yes += 1
                } else {
                    no += 1
                }
            }
        }
        assert!(yes > 10_000 && no > 10_000, "{yes} reached, {no} not");
    }

    #[test]
    fn survive_without_rates_keeps_existence() {
        let (r, log_q) = survive(0.7, 0.0, 0.0, 3.0);
        assert_eq!(r, 0.7);
        assert_eq!(log_q, 0.0);
    }

    #[test]
    fn survive_matches_closed_form() {
        let (r, mu, f, dt) = (0.9_f64, 0.2_f64, 1.5_f64, 0.4_f64);
        let stay = (-(mu + f) * dt).exp();
        let q = (1.0 - r) + r * (stay + mu / (mu + f) * (1.0 - stay));
        let (r_new, log_q) = survive(r, mu, f, dt);
        assert!((r_new - r * stay / q).abs() < 1e-15);
        assert!((log_q - q.ln()).abs() < 1e-15);
    }

    #[test]
    fn missed_outside_the_view_changes_nothing() {
        assert_eq!(missed(0.4, 0.0), (0.4, 0.0));
        let (r, log_q) = missed(1.0, 0.5);
        assert!((r - 1.0).abs() < 1e-15 && (log_q - 0.5_f64.ln()).abs() < 1e-15);
    }

    #[test]
    fn ndtr_known_values() {
        assert_eq!(ndtr(0.0), 0.5);
        assert!((ndtr(1.0) - 0.841_344_746_068_542_9).abs() < 1e-15);
        assert!((ndtr(-1.959_963_984_540_054) - 0.025).abs() < 1e-15);
        assert!((ndtr(-10.0) - 7.619_853_024_160_527e-24).abs() < 1e-37);
        assert_eq!(ndtr(40.0), 1.0);
        assert!(ndtr(f64::NAN).is_nan());
    }

    #[test]
    fn gauss_hermite_rule_integrates_moments() {
        let sum: f64 = GH_W.iter().sum();
        let second: f64 = GH_X.iter().zip(GH_W).map(|(x, w)| w * x * x).sum();
        let fourth: f64 = GH_X.iter().zip(GH_W).map(|(x, w)| w * x.powi(4)).sum();
        assert!((sum - 1.0).abs() < 1e-14);
        assert!((second - 1.0).abs() < 1e-13);
        assert!((fourth - 3.0).abs() < 1e-12);
    }

    #[test]
    fn inside_probability_of_a_centred_object() {
        // a box of +-1 sigma per axis: (Phi(1) - Phi(-1))^2
        let p = inside_probability(
            &[0.0, 0.0],
            &[1.0, 0.0, 0.0, 1.0],
            &[-1.0, -1.0],
            &[1.0, 1.0],
            None,
        );
        let axis = ndtr(1.0) - ndtr(-1.0);
        assert!((p - axis * axis).abs() < 1e-15);
        let wide = inside_probability(
            &[0.0, 0.0],
            &[1.0, 0.0, 0.0, 1.0],
            &[-1.0, -1.0],
            &[1.0, 1.0],
            Some(&[9.0, 9.0]),
        );
        assert!((wide - 1.0).abs() < 1e-15);
    }

    #[test]
    fn in_view_probability_half_plane() {
        let view = View {
            position: [0.0, 0.0],
            heading: 0.0,
            range: None,
            half_angle: Some(std::f64::consts::FRAC_PI_2),
        };
        // an object on the view's edge line, its spread symmetric: half in view
        let p = in_view_probability(&[0.0, 5.0], &[1.0, 0.0, 0.0, 1.0], 2, &view, None).unwrap();
        // the points on the edge line count as in view: 0.5 + w_3 / 2
        assert!((p - (0.5 + GH_W[3] * 0.5)).abs() < 1e-14, "{p}");
        let far =
            in_view_probability(&[100.0, 0.0], &[1.0, 0.0, 0.0, 1.0], 2, &view, None).unwrap();
        assert!((far - 1.0).abs() < 1e-14);
        let bad = in_view_probability(&[0.0, 0.0], &[-1.0, 0.0, 0.0, 1.0], 2, &view, None);
        assert!(matches!(bad, Err(KernelError::NotPositiveDefinite(_))));
    }
}
