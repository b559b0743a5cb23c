//! semwm-core: the numeric core of semwm's Multiple Hypothesis Filter, exposed to Python
//! as `semwm._core` (see docs/engines.md).
//!
//! One module per role of the Python engine, named like it, each citing the equations the
//! Python docstring cites: `filters::motion` (F(dt), Q(dt), the passive decay),
//! `filters::batched` (IMM mixing, prediction, update, combination), `filters::small`
//! (the small matrices: inverse, log determinant, the Mahalanobis gate) and
//! `filters::factory` (one class's filter); `mhf` (`semwm/mhf/`: the missed-detection
//! model's kernels, merging and pruning, the expansion of one scan, the observed rates). The Python engine is the specification;
//! the parity tests (tests/engines/) hold these kernels to it.

/// The extension's Rust allocations (versions, hypotheses, key sets: many small ones
/// per scan) go to mimalloc; Python's own memory is untouched.
#[global_allocator]
static ALLOCATOR: allocator::Mimalloc = allocator::Mimalloc;

pub mod allocator;
pub mod confidence;
pub mod error;
pub mod filters;
pub mod mhf;
mod python;
pub mod world;
