//! A detection checked against the knowledge and ready for the MHF, and where a scan's
//! sensor looked (`semwm/mhf/measurement.py`).

use std::sync::Arc;

use crate::mhf::existence::View;
use crate::mhf::rates::Name;
use crate::mhf::tables::{ClassId, DetectorId};

/// A detection with its measurement noise and clutter rate resolved (`Measurement`).
#[derive(Debug, Clone)]
pub struct Measurement {
    /// The detection's acceptance number: the lineage of the object it would start.
    pub seq: u64,
    pub time: f64,
    pub cls: ClassId,
    /// `d`: the measured position.
    pub z: Vec<f64>,
    /// `d x d`: its measurement noise.
    pub r: Arc<[f64]>,
    pub detector: DetectorId,
    /// Its source, `""` for none (the Python engine's `m.source or ""`).
    pub source: Name,
    pub label: Option<Name>,
    /// Hz: f_clutter of its detector.
    pub clutter_rate: f64,
    /// Where its sensor was (`sensor_position`), if given.
    pub sensor: Option<Vec<f64>>,
    /// s: the standard uncertainty of `time`.
    pub time_std: f64,
}

/// Where a scan's sensor looked (`SensorView`, paper 004's negative information).
#[derive(Debug, Clone)]
pub struct SensorView {
    pub time: f64,
    /// Its source, `""` for none.
    pub source: Name,
    /// The view's geometry (position, heading, range, half opening).
    pub view: View,
    /// Lineages of objects flagged as looked at (in view whatever their position).
    pub looking_at: Vec<u64>,
    /// The scan's detector, if the view names one.
    pub detector: Option<DetectorId>,
}

impl SensorView {
    pub fn looks_at(&self, lineage: u64) -> bool {
        self.looking_at.contains(&lineage)
    }
}

/// Whether a detection at `position` lies within its detector's `reach` of its sensor,
/// beyond it by no more than the margin of its noise `r` (`d x d`) along the line of
/// sight: `semwm.validation.out_of_range`'s test, `gate` its one-dimensional quantile
/// (`None` for a gate probability of 1: no margin), summed in the same order.
///
/// ```text
/// |z - s| <= reach + sqrt(gate u^T R u),  u = (z - s) / |z - s|
/// ```
pub fn within_reach_or_margin(
    position: &[f64],
    sensor: &[f64],
    reach: Option<f64>,
    r: &[f64],
    gate: Option<f64>,
) -> bool {
    let Some(reach) = reach else {
        return true;
    };
    let d = position.len();
    let mut offset = [0.0; 3];
    let mut squared = 0.0;
    for (i, (a, b)) in position.iter().zip(sensor).enumerate().take(3) {
        offset[i] = a - b;
        squared += offset[i] * offset[i];
    }
    let distance = squared.sqrt();
    if distance <= reach {
        return true;
    }
    let mut margin = 0.0;
    if let Some(gate) = gate {
        if distance > 0.0 && r.len() >= d * d && d <= 3 {
            let u: Vec<f64> = offset[..d].iter().map(|value| value / distance).collect();
            // (u R) u, in numpy's order, as the specification sums it
            let mut spread = 0.0;
            for j in 0..d {
                let mut w = 0.0;
                for i in 0..d {
                    w += u[i] * r[i * d + j];
                }
                spread += w * u[j];
            }
            let spread = if 0.0 > spread { 0.0 } else { spread }; // Python's max(spread, 0.0)
            margin = (gate * spread).sqrt();
        }
    }
    distance <= reach + margin
}

/// Whether every coordinate lies within the region's bounds widened by the noise
/// (`low <= value <= high` per axis, as `semwm.world._within`).
pub fn within_bounds(position: &[f64], low: &[f64], high: &[f64]) -> bool {
    position
        .iter()
        .zip(low.iter().zip(high))
        .all(|(value, (low, high))| *low <= *value && *value <= *high)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reach_is_inclusive_and_unbounded_without_a_range() {
        let r = [0.0; 4];
        assert!(within_reach_or_margin(
            &[3.0, 4.0],
            &[0.0, 0.0],
            Some(5.0),
            &r,
            None
        ));
        assert!(!within_reach_or_margin(
            &[3.0, 4.0],
            &[0.0, 0.0],
            Some(4.999),
            &r,
            None
        ));
        assert!(within_reach_or_margin(
            &[1e9, 0.0],
            &[0.0, 0.0],
            None,
            &r,
            None
        ));
        assert!(!within_reach_or_margin(
            &[f64::NAN, 0.0],
            &[0.0, 0.0],
            Some(1.0),
            &r,
            None
        ));
    }

    #[test]
    fn bounds_hold_every_axis_inclusively() {
        let (low, high) = ([0.0, 0.0], [1.0, 2.0]);
        assert!(within_bounds(&[0.0, 2.0], &low, &high));
        assert!(!within_bounds(&[0.5, 2.1], &low, &high));
        assert!(!within_bounds(&[-1e-12, 1.0], &low, &high));
        assert!(!within_bounds(&[f64::NAN, 1.0], &low, &high));
    }

    #[test]
    fn the_reach_has_the_noise_along_the_line_of_sight_as_margin() {
        // 5 m of range; R = diag(0.09, 1.0): 0.3 m along x, 1 m along y; gate 4 (2 sigma)
        let r = [0.09, 0.0, 0.0, 1.0];
        let sensor = [0.0, 0.0];
        let reach = Some(5.0);
        assert!(within_reach_or_margin(
            &[4.9, 0.0],
            &sensor,
            reach,
            &r,
            Some(4.0)
        ));
        assert!(within_reach_or_margin(
            &[5.59, 0.0],
            &sensor,
            reach,
            &r,
            Some(4.0)
        ));
        assert!(!within_reach_or_margin(
            &[5.61, 0.0],
            &sensor,
            reach,
            &r,
            Some(4.0)
        ));
        assert!(within_reach_or_margin(
            &[0.0, 6.99],
            &sensor,
            reach,
            &r,
            Some(4.0)
        ));
        assert!(!within_reach_or_margin(
            &[0.0, 7.01],
            &sensor,
            reach,
            &r,
            Some(4.0)
        ));
        assert!(!within_reach_or_margin(
            &[5.01, 0.0],
            &sensor,
            reach,
            &r,
            None
        ));
        assert!(within_reach_or_margin(
            &[50.0, 0.0],
            &sensor,
            None,
            &r,
            Some(4.0)
        ));
    }
}
