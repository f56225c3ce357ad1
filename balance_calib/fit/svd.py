"""The decompositions the rest of the package asks for, beside fit/least_squares.py's pivoted QR.

Minimum-norm least squares (LAPACK's SVD-based gelsd, as numpy.linalg.lstsq), singular values,
the SVD of a column-scaled matrix, an orthonormal basis of a matrix's columns (Householder QR)
and the unscaled coefficient covariance (XᵀX)⁻¹ of a design by SVD. Every module outside fit/
that needs one of these calls it here, so each decomposition has one home and one tolerance
convention. model/ cannot (fit/ imports model/): model/r091.py keeps its per-point pseudo-inverse.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from ..array_types import FloatArray


class MinimumNorm(NamedTuple):
    """The minimum-norm least-squares solution and the rank the tolerance gave."""

    solution: FloatArray  # (p,) or (p, k)
    rank: int


def minimum_norm_solve(
    matrix: ArrayLike, targets: ArrayLike, rcond: float | None = None
) -> MinimumNorm:
    """Minimise ``||targets - matrix · x||`` with the smallest ``||x||`` (numpy.linalg.lstsq).

    matrix (N, p), targets (N,) or (N, k). rcond: singular values below rcond x the largest are
    taken as zero, so the directions they span stay at zero (None: machine precision x max(N, p),
    numpy's default). Returns the solution, (p,) or (p, k), and the numerical rank of matrix.
    """
    solution, _, rank, _ = np.linalg.lstsq(
        np.asarray(matrix, dtype=float), np.asarray(targets, dtype=float), rcond=rcond
    )
    return MinimumNorm(solution, int(rank))


def singular_values(matrix: ArrayLike) -> FloatArray:
    """(min(N, p),) singular values of matrix (N, p), largest first."""
    values: FloatArray = np.linalg.svd(np.asarray(matrix, dtype=float), compute_uv=False)
    return values


class ScaledSvd(NamedTuple):
    """The thin SVD ``u · diag(s) · vt`` of matrix / scales, and those scales."""

    u: FloatArray  # (N, r)
    s: FloatArray  # (r,) largest first
    vt: FloatArray  # (r, p)
    scales: FloatArray  # (p,) column scales (1 for an all-zero column)


def column_norms(matrix: ArrayLike) -> FloatArray:
    """(p,) Euclidean norm of every column of matrix (N, p); 1 for an all-zero column."""
    norms: FloatArray = np.linalg.norm(np.asarray(matrix, dtype=float), axis=0)
    norms[norms == 0] = 1.0
    return norms


def scaled_svd(matrix: ArrayLike) -> ScaledSvd:
    """The thin SVD of matrix (N, p) with its columns scaled to unit norm (column_norms), so the
    singular values compare the columns' directions and not their units.
    """
    matrix = np.asarray(matrix, dtype=float)
    scales = column_norms(matrix)
    u, s, vt = np.linalg.svd(matrix / scales, full_matrices=False)
    return ScaledSvd(u, s, vt, scales)


def unscaled_covariance(design: ArrayLike) -> tuple[FloatArray, int]:
    """(XᵀX)⁻¹ (p, p) of design rows X (N, p), and the rank of X.

    By SVD of the unit-norm-scaled design; directions the rows do not determine (singular value
    not above 1e-10 of the largest) are left out, so they add nothing rather than infinity.
    """
    design = np.atleast_2d(np.asarray(design, dtype=float))
    _, singular, vt, scales = scaled_svd(design)
    keep = singular > singular[0] * 1e-10 if singular.size else np.zeros(0, bool)
    v_scaled = vt[keep].T / singular[keep]
    covariance: FloatArray = (v_scaled @ v_scaled.T) / np.outer(scales, scales)
    return covariance, int(keep.sum())


def orthonormal_columns(matrix: ArrayLike, tolerance: float) -> FloatArray:
    """(N, r) orthonormal basis of matrix's (N, p) column space by Householder QR (unpivoted): the
    columns of Q whose |R_jj| is above tolerance x max(|R_00|, 1e-300); a column that adds less
    than that to the ones before it adds no basis vector.
    """
    q, r = np.linalg.qr(np.asarray(matrix, dtype=float))
    keep = np.abs(np.diag(r)) > tolerance * max(float(np.abs(r[0, 0])), 1e-300)
    basis: FloatArray = q[:, keep]
    return basis
