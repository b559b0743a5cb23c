//! Coverage: what a scan without a sensor view could have seen, the numeric part of
//! `ObservedRates.watched` (`semwm/mhf/rates.py`, docs/knowledge.md "What semwm concludes
//! from not seeing something"), which is its specification.
//!
//! * Range coverage: a scan that gives its sensor's position, every detector of it with
//!   a `range`, covers an object with probability `Phi((range - d) / s)`, `d` the
//!   distance of its estimate from the sensor and `s` its spread (a hard cut
//!   `d <= range` without one).
//! * Learnt coverage: an object counts as in view when it lies within its margin of the
//!   convex hull of the scan's detections (a view is convex); `hull_distance` is how far
//!   outside the hull a point lies: the distance to the point for one corner, else the
//!   largest signed distance to the hull's facets (exact inside and along the faces, at
//!   most the true distance beyond a corner).

use crate::existence::ndtr;

/// A spread above this fraction of the reach makes `range_coverage` integrate over the
/// sensor's disc (ball): there its edge is not straight at the estimate's scale
/// (`semwm.mhf.rates.WIDE_SPREAD`).
pub const WIDE_SPREAD: f64 = 0.25;

/// The largest `(d / s)^2 / 2` for which `ball_probability` sums its series
/// (`semwm.mhf.rates.SERIES_CENTRE`).
pub const SERIES_CENTRE: f64 = 200.0;

/// Range coverage of one object at `x` from a sensor at `sensor` (the first
/// `k = min(len)` entries of each), the object isotropic Gaussian with std `spread`
/// around `x`: `Phi((reach - d) / max(spread, 1e-9))` where the spread is tight against
/// the reach or the estimate far from the sensor, else `ball_probability`; `d <= reach`
/// (1 or 0) without a spread.
pub fn range_coverage(x: &[f64], sensor: &[f64], reach: f64, spread: Option<f64>) -> f64 {
    let k = x.len().min(sensor.len());
    let squared: f64 = (0..k)
        .map(|i| (x[i] - sensor[i]) * (x[i] - sensor[i]))
        .sum();
    let distance = squared.sqrt();
    match spread {
        None => {
            if distance <= reach {
                1.0
            } else {
                0.0
            }
        }
        Some(s) => {
            let sd = s.max(1e-9);
            let scaled = distance / sd;
            if sd > WIDE_SPREAD * reach && 0.5 * scaled.powi(2) <= SERIES_CENTRE {
                ball_probability(scaled, reach / sd, k)
            } else {
                ndtr((reach - distance) / sd)
            }
        }
    }
}

/// `P(|X| <= radius)` for `X ~ N(mu, I_dim)`, `|mu| = centre`: the noncentral chi CDF
/// (`semwm.mhf.rates.ball_probability`, which gives the three forms): closed forms in
/// 1-D and 3-D, the Poisson mixture of central chi-square CDFs in 2-D.
pub fn ball_probability(centre: f64, radius: f64, dim: usize) -> f64 {
    let (a, b) = (centre, radius);
    if dim == 1 || dim > 3 {
        return ndtr(b - a) - ndtr(-b - a);
    }
    if dim == 3 {
        if a < 1e-8 {
            return 2.0 * ndtr(b) - 1.0 - 2.0 * b * normal_pdf(b);
        }
        return ndtr(b - a) - ndtr(-b - a) - (normal_pdf(b - a) - normal_pdf(b + a)) / a;
    }
    let (m, y) = (0.5 * a * a, 0.5 * b * b);
    let log_m = if m > 0.0 { m.ln() } else { f64::NEG_INFINITY };
    let log_y = if y > 0.0 { y.ln() } else { f64::NEG_INFINITY };
    let mut log_factorial = 0.0;
    let mut below = 0.0;
    let mut total = 0.0;
    let mut j: u32 = 0;
    loop {
        let jf = f64::from(j);
        if j > 0 {
            log_factorial += jf.ln();
        }
        below += if y > 0.0 {
            (-y + jf * log_y - log_factorial).exp()
        } else if j == 0 {
            1.0
        } else {
            0.0
        };
        let weight = if m > 0.0 {
            (-m + jf * log_m - log_factorial).exp()
        } else if j == 0 {
            1.0
        } else {
            0.0
        };
        total += weight * (1.0 - below).max(0.0);
        j += 1;
        let jf = f64::from(j);
        if m == 0.0 || (jf > m && weight * jf / (jf - m) < 1e-17) {
            break;
        }
    }
    total.clamp(0.0, 1.0)
}

fn normal_pdf(x: f64) -> f64 {
    (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt()
}

/// One facet of a 2-D hull: outward unit normal `n` and offset `c`, `n . x + c` the
/// signed distance (positive outside), as qhull's `equations` give it.
#[derive(Debug, Clone, Copy)]
pub struct Facet {
    pub normal: [f64; 2],
    pub offset: f64,
}

/// Below this ratio of the hull's area to the square of its extent, the corners count
/// as on one line: there the specification asks qhull, whose own tolerance decides
/// between a thin hull and the segment, so the Rust engine leaves such scans to it.
pub const FLAT: f64 = 1e-6;

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// The facets of the convex hull of `corners` (2-D, at least three, not nearly on one
/// line), by Andrew's monotone chain; `None` for corners the hull of which is flat
/// (see [`FLAT`]).
pub fn hull_facets(corners: &[[f64; 2]]) -> Option<Vec<Facet>> {
    if corners.len() < 3 {
        return None;
    }
    let mut points: Vec<[f64; 2]> = corners.to_vec();
    points.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    points.dedup();
    if points.len() < 3 {
        return None;
    }
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(points.len() * 2);
    for pass in 0..2 {
        let start = hull.len();
        let ordered: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(points.iter())
        } else {
            Box::new(points.iter().rev())
        };
        for &p in ordered {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop(); // the last point starts the other chain
    }
    if hull.len() < 3 {
        return None;
    }
    // area (shoelace) against the extent: a nearly flat hull is left to the specification
    let area: f64 = (0..hull.len())
        .map(|i| {
            let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
            a[0] * b[1] - a[1] * b[0]
        })
        .sum::<f64>()
        * 0.5;
    let (mut lo, mut hi) = (points[0], points[0]);
    for p in &points {
        lo = [lo[0].min(p[0]), lo[1].min(p[1])];
        hi = [hi[0].max(p[0]), hi[1].max(p[1])];
    }
    let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    if area.is_nan() || area <= FLAT * extent * extent {
        return None;
    }
    // counter-clockwise: the outward normal of edge a -> b is (b_y - a_y, a_x - b_x)
    let facets = (0..hull.len())
        .map(|i| {
            let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
            let (nx, ny) = (b[1] - a[1], a[0] - b[0]);
            let length = (nx * nx + ny * ny).sqrt();
            let normal = [nx / length, ny / length];
            Facet {
                normal,
                offset: -(normal[0] * a[0] + normal[1] * a[1]),
            }
        })
        .collect();
    Some(facets)
}

/// How far `x` lies outside the hull with `facets` (0 inside): the largest signed
/// distance to a facet, at least 0.
pub fn outside(x: [f64; 2], facets: &[Facet]) -> f64 {
    let signed = facets
        .iter()
        .map(|f| x[0] * f.normal[0] + x[1] * f.normal[1] + f.offset)
        .fold(f64::NEG_INFINITY, f64::max);
    signed.max(0.0)
}

/// The distance from `x` to the point `corner`.
pub fn distance(x: &[f64], corner: &[f64]) -> f64 {
    x.iter()
        .zip(corner)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_square() {
        let facets = hull_facets(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5]])
            .expect("a square is not flat");
        assert_eq!(facets.len(), 4);
        assert_eq!(outside([0.5, 0.5], &facets), 0.0);
        assert!((outside([3.0, 0.5], &facets) - 2.0).abs() < 1e-15);
        assert!((outside([0.5, -0.25], &facets) - 0.25).abs() < 1e-15);
        // beyond a corner: at most the true distance (here the larger axis offset)
        assert!((outside([2.0, 3.0], &facets) - 2.0).abs() < 1e-15);
    }

    #[test]
    fn flat_corners_are_left_to_the_specification() {
        assert!(hull_facets(&[[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]).is_none());
        assert!(hull_facets(&[[0.0, 0.0], [1.0, 1e-9], [2.0, 0.0]]).is_none());
        assert!(hull_facets(&[[0.0, 0.0], [1.0, 0.0]]).is_none());
    }

    #[test]
    fn range_coverage_hard_and_soft() {
        assert_eq!(range_coverage(&[3.0, 4.0], &[0.0, 0.0], 5.0, None), 1.0);
        assert_eq!(range_coverage(&[3.0, 4.1], &[0.0, 0.0], 5.0, None), 0.0);
        assert_eq!(
            range_coverage(&[3.0, 4.0, 7.0], &[0.0, 0.0], 5.0, Some(1.0)),
            0.5
        );
    }

    #[test]
    fn a_wide_spread_is_covered_by_the_discs_share_of_it() {
        // scipy.stats.ncx2.cdf(b**2, 2, a**2) and chi2.cdf(1, 3)
        assert!((ball_probability(3.0, 1.0, 2) - 0.010_829_449_821_547_85).abs() < 1e-13);
        assert!((ball_probability(0.0, 1.0, 3) - 0.198_748_043_098_799_15).abs() < 1e-13);
        assert!((ball_probability(20.0, 20.0, 2) - 0.490_023_321_859_030_5).abs() < 1e-13);
        // a ball 400 m spread, 2 m from a sensor of 5 m reach: about r^2 / 2 s^2
        let covered = range_coverage(&[2.0, 0.0], &[0.0, 0.0], 5.0, Some(400.0));
        assert!((covered - 25.0 / (2.0 * 400.0 * 400.0)).abs() < 1e-6);
    }
}
