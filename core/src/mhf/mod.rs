//! The Multiple Hypothesis Filter, module by module as `semwm/mhf/` holds it:
//! `tables` (the knowledge's numeric tables), `state` (object versions and the
//! filter's state), `measurement`, `predict`, `classes` (class distributions and
//! confusion), `association` (gates, updates and each detection's options, eqs. 4-8),
//! `existence` and `coverage` (the missed-detection model's kernels), `hypotheses`
//! (merging and pruning, eq. 3; `semwm/mhf/prune.py`), `expansion` (the hypothesis
//! algebra of one scan, eqs. 1 and 4-8), `similar` (twin merging), `rates` (the
//! detection rates observed on the sources' streams) and `filter` (one scan, from a
//! state to the next).

pub mod association;
pub mod classes;
pub mod coverage;
pub mod existence;
pub mod expansion;
pub mod filter;
pub mod hypotheses;
pub mod measurement;
pub mod predict;
pub mod rates;
pub mod similar;
pub mod state;
pub mod tables;
