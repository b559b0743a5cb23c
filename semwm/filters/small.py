"""Closed forms for the small symmetric matrices of tracking (``d <= 2``), batched.

A position covariance is 2x2 in the plane. For stacks of such small matrices numpy's
``linalg`` routines cost tens of microseconds per call in dispatch and checks, far
more than the arithmetic, so for ``d <= 2`` these helpers write the inverse,
determinant and largest eigenvalue out; larger matrices go to ``numpy.linalg``.
Every helper takes stacks ``(..., d, d)`` of symmetric matrices.

.. math::
   S = \\begin{pmatrix} a & b \\\\ b & c \\end{pmatrix}, \\quad
   |S| = ac - b^2, \\quad
   S^{-1} = \\frac{1}{|S|} \\begin{pmatrix} c & -b \\\\ -b & a \\end{pmatrix}, \\quad
   \\lambda_{max} = \\tfrac{a + c}{2} + \\sqrt{\\big(\\tfrac{a - c}{2}\\big)^2 + b^2}
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def inverse_and_log_det(S: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``S^{-1}`` and ``log |S|`` of symmetric positive definite ``S`` ``(..., d, d)``.

    Raises ``numpy.linalg.LinAlgError`` when a matrix is not positive definite.
    """
    d = S.shape[-1]
    if d == 2:
        a, b, c = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
        det = a * c - b * b
        if det.size == 0 or (det.min() > 0.0 and a.min() > 0.0):
            inverse = np.empty_like(S)
            inverse[..., 0, 0] = c / det
            inverse[..., 1, 1] = a / det
            inverse[..., 0, 1] = inverse[..., 1, 0] = -b / det
            return inverse, np.log(det)
    elif d == 1 and (S.size == 0 or S.min() > 0.0):
        return 1.0 / S, np.log(S[..., 0, 0])
    np.linalg.cholesky(S)  # raises when S is not positive definite
    _, log_det = np.linalg.slogdet(S)
    general: FloatArray = np.asarray(np.linalg.inv(S), dtype=np.float64)
    return general, np.asarray(log_det, dtype=np.float64)


def quadratic_form(residual: FloatArray, inverse: FloatArray) -> FloatArray:
    """:math:`r^T C^{-1} r` from ``inverse`` :math:`C^{-1}` ``(..., d, d)``."""
    result: FloatArray = np.einsum("...i,...ij,...j->...", residual, inverse, residual)
    return result


def mahalanobis_squared(residual: FloatArray, covariance: FloatArray) -> FloatArray:
    """:math:`r^T C^{-1} r` for stacked residuals ``(..., d)`` and covariances ``(..., d, d)``."""
    if covariance.shape[-1] == 2:
        a, b, c = covariance[..., 0, 0], covariance[..., 0, 1], covariance[..., 1, 1]
        r0, r1 = residual[..., 0], residual[..., 1]
        result: FloatArray = (c * r0 * r0 - 2.0 * b * r0 * r1 + a * r1 * r1) / (a * c - b * b)
        return result
    solved = np.linalg.solve(covariance, residual[..., None])[..., 0]
    general: FloatArray = np.einsum("...i,...i->...", residual, solved)
    return general


def largest_eigenvalue(C: FloatArray) -> FloatArray:
    """The largest eigenvalue of each symmetric ``C`` ``(..., d, d)``."""
    d = C.shape[-1]
    if d == 2:
        a, b, c = C[..., 0, 0], C[..., 0, 1], C[..., 1, 1]
        half = 0.5 * (a - c)
        result: FloatArray = 0.5 * (a + c) + np.sqrt(half * half + b * b)
        return result
    if d == 1:
        return C[..., 0, 0].copy()
    largest: FloatArray = np.asarray(np.linalg.eigvalsh(C)[..., -1], dtype=np.float64)
    return largest
