//! semwm-core: the numeric core of semwm's Multiple Hypothesis Filter, exposed to Python
//! as `semwm._core` (see docs/engines.md).
//!
//! One module per role of the Python engine, named like it, each citing the equations the
//! Python docstring cites: `filters::motion` (F(dt), Q(dt), the passive decay),
//! `filters::batched` (IMM mixing, prediction, update, combination), `filters::small`
//! (the small matrices: inverse, log determinant, the Mahalanobis gate) and
//! `filters::factory` (one class's filter); `existence` and `coverage` (the
//! missed-detection model); `hypotheses` (merging and pruning, eq. 3) and `expansion`
//! (the hypothesis algebra of one scan, eqs. 1 and 4-8); `rates` (the detection rates
//! observed on the sources' streams, the state kept between scans). The Python engine is the specification;
//! the parity tests (tests/engines/) hold these kernels to it.

pub mod coverage;
pub mod error;
pub mod existence;
pub mod expansion;
pub mod filters;
pub mod hypotheses;
mod python;
mod python_rates;
pub mod rates;
