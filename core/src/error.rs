//! Errors of the numeric kernels. Every kernel returns `Result`; the Python bindings
//! (`crate::python`) turn each variant into a Python exception with its message, so that
//! no panic and no bare error code reaches Python.

use std::fmt;

/// What went wrong in a kernel call.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum KernelError {
    /// An argument's shape does not fit the others: names the argument, what was
    /// expected and what was given (raised as `ValueError`).
    Shape(String),
    /// A matrix that must be symmetric positive definite is not (raised as
    /// `numpy.linalg.LinAlgError`, as the Python engine's `numpy.linalg` calls raise).
    NotPositiveDefinite(String),
    /// A matrix to solve with is singular (raised as `numpy.linalg.LinAlgError`).
    Singular(String),
    /// A value the computation cannot take, where the Python engine raises `ValueError`
    /// (every hypothesis with zero probability, the logarithm of a rate that is not
    /// positive): raised as `ValueError` with the same message.
    Value(String),
}

impl fmt::Display for KernelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            KernelError::Shape(message)
            | KernelError::NotPositiveDefinite(message)
            | KernelError::Singular(message)
            | KernelError::Value(message) => f.write_str(message),
        }
    }
}

impl std::error::Error for KernelError {}

pub type KernelResult<T> = Result<T, KernelError>;

/// `Err(Shape)` unless `got == expected`, naming the argument.
pub fn expect_shape(name: &str, got: &[usize], expected: &[usize]) -> KernelResult<()> {
    if got == expected {
        Ok(())
    } else {
        Err(KernelError::Shape(format!(
            "{name}: expected shape {expected:?}, got {got:?}"
        )))
    }
}
