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

use crate::mhf::existence::ndtr;

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

/// One facet of a hull: outward unit normal `n` (`d` entries) and offset `c`,
/// `n . x + c` the signed distance (positive outside), as qhull's `equations` give it.
#[derive(Debug, Clone)]
pub struct Facet {
    pub normal: Vec<f64>,
    pub offset: f64,
}

/// Corners whose smallest singular value (centred) is at most this fraction of their
/// largest lie on one line or plane (`semwm.mhf.rates.FLAT`): measured to the segment
/// of their extremes.
pub const FLAT: f64 = 1e-6;

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// The facets of the convex hull of 2-D `corners` by Andrew's monotone chain; `None`
/// when fewer than three corners are on it.
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
    // counter-clockwise: the outward normal of edge a -> b is (b_y - a_y, a_x - b_x)
    let facets = (0..hull.len())
        .map(|i| {
            let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
            let (nx, ny) = (b[1] - a[1], a[0] - b[0]);
            let length = (nx * nx + ny * ny).sqrt();
            let normal = vec![nx / length, ny / length];
            let offset = -(normal[0] * a[0] + normal[1] * a[1]);
            Facet { normal, offset }
        })
        .collect();
    Some(facets)
}

/// The facets of the convex hull of 3-D `corners` (not on one plane): every plane
/// through three corners with all the corners on one side of it (within rounding),
/// oriented outward. Scans hold a few detections, so the cubic search is cheap; a face
/// with more than three corners appears once per triangle of it, which changes no
/// signed distance.
pub fn hull_facets_3d(corners: &[[f64; 3]]) -> Vec<Facet> {
    let m = corners.len();
    let extent = corners
        .iter()
        .flat_map(|c| c.iter())
        .fold(0.0_f64, |top, v| top.max(v.abs()))
        .max(1e-300);
    let tolerance = 1e-12 * extent;
    let mut facets = Vec::new();
    for i in 0..m {
        for j in i + 1..m {
            for k in j + 1..m {
                let (a, b, c) = (corners[i], corners[j], corners[k]);
                let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
                let n = [
                    u[1] * v[2] - u[2] * v[1],
                    u[2] * v[0] - u[0] * v[2],
                    u[0] * v[1] - u[1] * v[0],
                ];
                let length = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                if length.is_nan() || length <= 0.0 {
                    continue; // three corners on one line
                }
                let n = [n[0] / length, n[1] / length, n[2] / length];
                let offset = -(n[0] * a[0] + n[1] * a[1] + n[2] * a[2]);
                let (mut above, mut below) = (false, false);
                for p in corners {
                    let signed = n[0] * p[0] + n[1] * p[1] + n[2] * p[2] + offset;
                    above |= signed > tolerance;
                    below |= signed < -tolerance;
                }
                match (above, below) {
                    (false, _) => facets.push(Facet {
                        normal: n.to_vec(),
                        offset,
                    }),
                    (true, false) => facets.push(Facet {
                        normal: vec![-n[0], -n[1], -n[2]],
                        offset: -offset,
                    }),
                    (true, true) => {}
                }
            }
        }
    }
    facets
}

/// How far `x` lies outside the hull with `facets` (0 inside): the largest signed
/// distance to a facet, at least 0.
pub fn outside(x: &[f64], facets: &[Facet]) -> f64 {
    let signed = facets
        .iter()
        .map(|f| {
            let mut total = 0.0;
            for (a, b) in x.iter().zip(&f.normal) {
                total += a * b;
            }
            total + f.offset
        })
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

/// The eigenvalues (descending) and unit eigenvectors of a symmetric `d x d` matrix
/// (`d <= 3`), by cyclic Jacobi rotations.
pub fn symmetric_eigen(matrix: &[f64], d: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    let mut a = [[0.0; 3]; 3];
    let mut v = [[0.0; 3]; 3];
    for i in 0..d {
        for j in 0..d {
            a[i][j] = matrix[i * d + j];
        }
        v[i][i] = 1.0;
    }
    for _ in 0..64 {
        let off: f64 = (0..d)
            .flat_map(|i| (0..d).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        let scale: f64 = (0..d).map(|i| a[i][i] * a[i][i]).sum();
        if off <= 1e-36 * scale || off == 0.0 {
            break;
        }
        for p in 0..d {
            for q in p + 1..d {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in a.iter_mut().take(d) {
                    let (akp, akq) = (row[p], row[q]);
                    row[p] = c * akp - s * akq;
                    row[q] = s * akp + c * akq;
                }
                let (row_p, row_q) = (a[p], a[q]);
                for k in 0..d {
                    a[p][k] = c * row_p[k] - s * row_q[k];
                    a[q][k] = s * row_p[k] + c * row_q[k];
                }
                for row in v.iter_mut().take(d) {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut order: Vec<usize> = (0..d).collect();
    order.sort_by(|&x, &y| a[y][y].total_cmp(&a[x][x]));
    let values = order.iter().map(|&i| a[i][i]).collect();
    let vectors = order
        .iter()
        .map(|&i| (0..d).map(|k| v[k][i]).collect())
        .collect();
    (values, vectors)
}

/// `hull_distance`: how far each point (`points`, `N x d` row-major) lies outside the
/// convex hull of `corners` (`M x d`), 0 inside: the distance to the point for one
/// corner; to the segment of the extremes for fewer than `d + 1` corners or corners on
/// one line or plane (`FLAT`); otherwise the largest signed distance to the hull's
/// facets (exact inside and along the faces, at most the true distance beyond a corner).
pub fn hull_distance(points: &[f64], corners: &[f64], d: usize) -> Vec<f64> {
    let n = points.len().checked_div(d).unwrap_or(0);
    let m = corners.len().checked_div(d).unwrap_or(0);
    let point = |i: usize| &points[i * d..(i + 1) * d];
    if m == 1 {
        return (0..n).map(|i| distance(point(i), corners)).collect();
    }
    let mut mean = vec![0.0; d];
    for j in 0..m {
        for a in 0..d {
            mean[a] += corners[j * d + a];
        }
    }
    for value in &mut mean {
        *value /= m as f64;
    }
    let centred: Vec<f64> = (0..m * d).map(|k| corners[k] - mean[k % d]).collect();
    let mut scatter = vec![0.0; d * d];
    for j in 0..m {
        for a in 0..d {
            for b in 0..d {
                scatter[a * d + b] += centred[j * d + a] * centred[j * d + b];
            }
        }
    }
    let (values, vectors) = symmetric_eigen(&scatter, d);
    let largest = values[0].max(0.0).sqrt();
    let smallest = values[d - 1].max(0.0).sqrt();
    if m > d && smallest > FLAT * largest && (d == 2 || d == 3) {
        let facets = if d == 2 {
            let hull: Vec<[f64; 2]> = (0..m)
                .map(|j| [corners[2 * j], corners[2 * j + 1]])
                .collect();
            hull_facets(&hull).unwrap_or_default()
        } else {
            let hull: Vec<[f64; 3]> = (0..m)
                .map(|j| [corners[3 * j], corners[3 * j + 1], corners[3 * j + 2]])
                .collect();
            hull_facets_3d(&hull)
        };
        if !facets.is_empty() {
            return (0..n).map(|i| outside(point(i), &facets)).collect();
        }
    }
    // the segment of the extremes along the corners' principal direction
    let direction = &vectors[0];
    let along: Vec<f64> = (0..m)
        .map(|j| (0..d).map(|a| centred[j * d + a] * direction[a]).sum())
        .collect();
    let low = along.iter().copied().fold(f64::INFINITY, f64::min);
    let high = along.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let start: Vec<f64> = (0..d).map(|a| mean[a] + low * direction[a]).collect();
    let end: Vec<f64> = (0..d).map(|a| mean[a] + high * direction[a]).collect();
    let ab: Vec<f64> = (0..d).map(|a| end[a] - start[a]).collect();
    let length: f64 = ab.iter().map(|v| v * v).sum();
    (0..n)
        .map(|i| {
            let x = point(i);
            let t = if length > 0.0 {
                ((0..d).map(|a| (x[a] - start[a]) * ab[a]).sum::<f64>() / length).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let nearest: Vec<f64> = (0..d).map(|a| start[a] + t * ab[a]).collect();
            distance(x, &nearest)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_square() {
        let square = [0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0, 0.5, 0.5];
        let points = [0.5, 0.5, 3.0, 0.5, 0.5, -0.25, 2.0, 3.0];
        let got = hull_distance(&points, &square, 2);
        // beyond a corner: at most the true distance (here the larger axis offset)
        let expected = [0.0, 2.0, 0.25, 2.0];
        for (g, e) in got.iter().zip(expected) {
            assert!((g - e).abs() < 1e-15, "{got:?}");
        }
    }

    #[test]
    fn flat_corners_measure_to_the_segment_of_their_extremes() {
        let line = [0.0, 0.0, 1.0, 1.0, 2.0, 2.0];
        let got = hull_distance(&[3.0, 3.0, 1.0, 0.0, -1.0, -1.0], &line, 2);
        let expected = [2.0_f64.sqrt(), 0.5_f64.sqrt(), 2.0_f64.sqrt()];
        for (g, e) in got.iter().zip(expected) {
            assert!((g - e).abs() < 1e-14, "{got:?}");
        }
        // two corners: the segment; nearly on one line: the segment too
        let two = hull_distance(&[0.5, 1.0], &[0.0, 0.0, 1.0, 0.0], 2);
        assert!((two[0] - 1.0).abs() < 1e-15);
        let thin = hull_distance(&[1.0, 1.0], &[0.0, 0.0, 1.0, 1e-9, 2.0, 0.0], 2);
        assert!((thin[0] - 1.0).abs() < 1e-8);
    }

    #[test]
    fn a_cube_in_three_dimensions() {
        let mut cube = Vec::new();
        for i in 0..8 {
            cube.extend([(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64]);
        }
        let got = hull_distance(&[0.5, 0.5, 0.5, 0.5, 0.5, 3.0, -2.0, 0.5, 0.5], &cube, 3);
        let expected = [0.0, 2.0, 2.0];
        for (g, e) in got.iter().zip(expected) {
            assert!((g - e).abs() < 1e-14, "{got:?}");
        }
    }

    #[test]
    fn symmetric_eigen_of_a_known_matrix() {
        let (values, vectors) = symmetric_eigen(&[2.0, 1.0, 1.0, 2.0], 2);
        assert!((values[0] - 3.0).abs() < 1e-14 && (values[1] - 1.0).abs() < 1e-14);
        let v = &vectors[0];
        assert!((v[0].abs() - 0.5_f64.sqrt()).abs() < 1e-14 && (v[0] - v[1]).abs() < 1e-14);
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
