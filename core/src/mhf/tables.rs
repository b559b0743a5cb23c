//! The knowledge's numeric tables, as the filter reads them: what
//! `MultipleHypothesisFilter`, its `Associator` and its `ClassModel`
//! (`semwm/mhf/filter.py`, `association.py`, `classes.py`) compute from the knowledge
//! once. The Python side computes every value here with the Python engine's own code
//! (`semwm/mhf/core_engine.py: tables`) and hands them over once per knowledge, so the
//! two engines start from the same numbers; knowledge, validation and the filter factory
//! stay in Python.
//!
//! Classes are numbered in the order of their sorted names (the `ClassModel`'s class
//! space: a version's class distribution is indexed the same way), detectors in the
//! order the Python side lists them.

use crate::error::{KernelError, KernelResult};
use crate::filters::factory::ClassTables;
use crate::mhf::rates::Name;

/// A class, by its index among the knowledge's sorted class names.
pub type ClassId = usize;
/// A detector, by its index in `Tables::detectors`.
pub type DetectorId = usize;

/// A disappearance relation near a known object: a class leaves at `frequency` (Hz)
/// within `max_distance` (m) of `target` (paper 002 eq. 4, mirrored; `near_rate`).
#[derive(Debug, Clone)]
pub struct LeaveRelation {
    pub target: Vec<f64>,
    pub max_distance: f64,
    pub frequency: f64,
}

/// An appearance relation of a class (paper 002 eq. 4): new objects appear at
/// `frequency` (Hz) within `max_distance` (m) of an object of a class `covered` holds.
#[derive(Debug, Clone)]
pub struct Appearance {
    /// Per class: whether the relation's target covers it (the class or a subclass).
    pub covered: Vec<bool>,
    pub frequency: f64,
    pub max_distance: f64,
    /// `log(frequency) + log spatial density` of a birth within `max_distance` (`mht`:
    /// uniform over the disc or ball; `paper`: no density).
    pub log_num: f64,
    /// Positions of the known (mapped) objects of a covered class.
    pub known: Vec<Vec<f64>>,
}

/// One class of the knowledge.
#[derive(Debug, Clone)]
pub struct ClassSpec {
    /// Shared: the observed rates keep it per object and scan without a copy.
    pub name: Name,
    pub filter: ClassTables,
    /// `n x n`: a new object's state covariance.
    pub initial_covariance: Vec<f64>,
    /// `M`.
    pub initial_mode_probabilities: Vec<f64>,
    /// Hz: f_existing, the rate of its detections while in view.
    pub detection_frequency: f64,
    /// Per scan, P_D in a sensor's view.
    pub detection_probability: f64,
    /// Hz: mu, the rate at which it leaves.
    pub leave_frequency: f64,
    /// Hz: f_new, the base rate of its births.
    pub new_frequency: f64,
    /// P_max (infinite: none).
    pub max_position_variance: f64,
    /// C3's longest time unseen (s; infinite: none).
    pub max_time_without_update: f64,
    /// `d`: its region margins (`MultipleHypothesisFilter.region_margins`).
    pub region_margin: Vec<f64>,
    /// `d`: the caps of its position variances for the region (infinite: none).
    pub region_cap: Vec<f64>,
    pub leave_relations: Vec<LeaveRelation>,
    pub appearance: Vec<Appearance>,
    /// Whether a new object may be of this class (births or an appearance relation).
    pub can_appear: bool,
    /// Paper 004 IV-B: the prior that a reported kick connected.
    pub kick_probability: f64,
    /// Paper 004's confidence: its decay while unseen (1/s), while a view looks at it
    /// and does not report it (1/s), and per metre its observer moved (1/m).
    pub confidence_decay: f64,
    pub looking_decay: f64,
    pub confidence_decay_distance: f64,
}

/// One detector of the knowledge.
#[derive(Debug, Clone)]
pub struct DetectorSpec {
    /// Shared: the observed rates keep it per scan without a copy.
    pub name: Name,
    /// log of the clutter's spatial density over its coverage (`mht`; 0 without one).
    pub clutter_log_density: f64,
    /// `K x K`, `[reported class][true class]`: L(reported | true), its confusion model
    /// (a report's likelihoods over the true classes are a row).
    pub likelihood: Vec<f64>,
    /// m, from its sensor (`None`: unbounded).
    pub range: Option<f64>,
    /// Declared static: it sees the whole region (or `range` around `position`).
    pub fixed: bool,
    pub position: Option<Vec<f64>>,
    /// The confidence a detection of it sets (paper 004).
    pub confidence: f64,
}

/// The filter's settings and the knowledge's numeric tables.
#[derive(Debug, Clone)]
pub struct Tables {
    pub dim: usize,
    pub classes: Vec<ClassSpec>,
    pub detectors: Vec<DetectorSpec>,
    pub default_detector: DetectorId,
    /// `association_model: mht` (else `paper`).
    pub mht: bool,
    /// `mht` and `world.missed_detection_term`.
    pub missed_detections: bool,
    /// `mht` and `world.observed_detection_rates`.
    pub observed_rates: bool,
    /// alpha of eq. (3).
    pub ratio: f64,
    pub max_hypotheses: usize,
    /// `world.merge_distance` under `mht`, else 0.
    pub merge_distance: f64,
    /// `world.removal_existence` under `mht`, else 0.
    pub removal_existence: f64,
    /// Axis-aligned bounds per axis.
    pub region: Option<Vec<(f64, f64)>>,
    /// The chi-square gate (`dim` degrees of freedom; infinite: no gate).
    pub gate: f64,
    /// `sqrt(chi2_1 quantile of gate_probability)`: a margin in standard deviations.
    pub gate_quantile: f64,
    /// m: a labelled detection may update its label's holder this far away.
    pub label_gate: f64,
    pub log_label_error: f64,
    /// log of the births' volume (0 without one).
    pub log_volume: f64,
    /// `K x K`: `subtree[i][j] = 1` when class `j` is `i` or one of its descendants.
    pub subtree: Vec<f64>,
    /// `K`: the number of ancestors of each class.
    pub depth: Vec<f64>,
    /// `K`: 1 for the classes new objects may be of.
    pub appear_mask: Vec<f64>,
    /// `K x K`: the taxonomy's `compatible` (one is the other or its ancestor).
    pub compatible: Vec<bool>,
    /// `K x K`: paper 002 eq. (8)'s class likelihood (`paper`: 0 or 1).
    pub class_likelihood: Vec<f64>,
    /// `K x K`: the more specific of two compatible classes (`paper`), else `None`.
    pub most_specific: Vec<Option<ClassId>>,
    pub min_existence: f64,
}

impl Tables {
    /// The number of classes.
    pub fn class_count(&self) -> usize {
        self.classes.len()
    }

    /// Checks the tables' sizes against each other.
    pub fn validate(&self) -> KernelResult<()> {
        let k = self.classes.len();
        let d = self.dim;
        let shape = |name: &str, got: usize, expected: usize| {
            if got == expected {
                Ok(())
            } else {
                Err(KernelError::Shape(format!(
                    "{name}: expected {expected} values, got {got}"
                )))
            }
        };
        if !(1..=3).contains(&d) {
            return Err(KernelError::Shape(format!("dim: expected 1 to 3, got {d}")));
        }
        for class in &self.classes {
            class.filter.validate()?;
            let (m, n) = (class.filter.modes, class.filter.state);
            shape(&class.name, class.filter.dim, d)?;
            shape("initial_covariance", class.initial_covariance.len(), n * n)?;
            shape(
                "initial_mode_probabilities",
                class.initial_mode_probabilities.len(),
                m,
            )?;
            shape("region_margin", class.region_margin.len(), d)?;
            shape("region_cap", class.region_cap.len(), d)?;
            for relation in &class.leave_relations {
                shape("leave relation target", relation.target.len(), d)?;
            }
            for relation in &class.appearance {
                shape("appearance covered", relation.covered.len(), k)?;
                for known in &relation.known {
                    shape("appearance known object", known.len(), d)?;
                }
            }
        }
        for detector in &self.detectors {
            shape(&detector.name, detector.likelihood.len(), k * k)?;
        }
        if self.default_detector >= self.detectors.len() {
            return Err(KernelError::Shape(format!(
                "default_detector: expected an index below {}, got {}",
                self.detectors.len(),
                self.default_detector
            )));
        }
        if let Some(region) = &self.region {
            shape("region", region.len(), d)?;
        }
        shape("subtree", self.subtree.len(), k * k)?;
        shape("depth", self.depth.len(), k)?;
        shape("appear_mask", self.appear_mask.len(), k)?;
        shape("compatible", self.compatible.len(), k * k)?;
        shape("class_likelihood", self.class_likelihood.len(), k * k)?;
        shape("most_specific", self.most_specific.len(), k * k)?;
        Ok(())
    }

    /// `log(alpha)` of eq. (3), `-inf` without ratio pruning.
    pub fn log_ratio(&self) -> f64 {
        if self.ratio > 0.0 {
            self.ratio.ln()
        } else {
            f64::NEG_INFINITY
        }
    }

    /// Whether a class's filter has a velocity (it crosses the region's edge by
    /// entering and leaving).
    pub fn moves(&self, class: ClassId) -> bool {
        self.classes[class].filter.state > self.dim
    }
}
