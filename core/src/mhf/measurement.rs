//! A detection checked against the knowledge and ready for the MHF, and where a scan's
//! sensor looked (`semwm/mhf/measurement.py`).

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
    pub r: Vec<f64>,
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
