"""Right inverses of the Jacobian: the correction matrix C (Sect. 5, eq 48) and regularized variants.

All inverses are computed in *scaled* coordinates — parameters divided by their
scales, errors by theirs — so that "small singular value" means "a direction
that barely moves the errors that matter", independent of units. The plain
inverse and the eq 48 pseudo-inverse are scale invariant, so scaling changes
nothing for them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from aerobat.errors import ConfigError

__all__ = ["CorrectionKind", "RegularizedKind", "SvdInfo", "correction_matrix", "svd_info"]

RegularizedKind = Literal["tsvd", "damped"]
"""The regularized inverses: truncated SVD or damped (the learning rules' filter factors too)."""
CorrectionKind = Literal["inverse", RegularizedKind]
"""The right inverses a correction matrix is built with: the plain pseudo-inverse or a regularized one."""


@dataclass(frozen=True)
class SvdInfo:
    """Singular values of the scaled Jacobian and its condition number."""

    singular_values: np.ndarray
    condition_number: float
    rank: int


def svd_info(J: np.ndarray, param_scales: np.ndarray, error_scales: np.ndarray, *, rtol: float = 1e-10) -> SvdInfo:
    Js = (J / error_scales[:, None]) * param_scales[None, :]
    s = np.linalg.svd(Js, compute_uv=False)
    rank = int(np.sum(s > rtol * s[0])) if s.size and s[0] > 0 else 0
    cond = float(s[0] / s[-1]) if s.size and s[-1] > 0 else float("inf")
    return SvdInfo(singular_values=s, condition_number=cond, rank=rank)


def correction_matrix(
    J: np.ndarray,
    param_scales: np.ndarray,
    error_scales: np.ndarray,
    *,
    kind: CorrectionKind = "inverse",
    tsvd_rtol: float = 1e-3,
    damping: float = 1e-3,
) -> np.ndarray:
    """A right inverse C of J (J C ≈ I): ``p ← p − γ C e``.

    Parameters
    ----------
    J : (n_err, n_par) Jacobian ∂e/∂p.
    param_scales, error_scales : (n_par,), (n_err,) typical magnitudes.
    kind : ``"inverse"`` — J⁻¹ if square, else Jᵀ(JJᵀ)⁻¹ (eq 48);
        ``"tsvd"`` — truncated SVD, dropping scaled singular values below
        ``tsvd_rtol`` × the largest;
        ``"damped"`` — damped least squares Jᵀ(JJᵀ + λ²σ₁²I)⁻¹ with λ = ``damping``.
    """
    n_err, n_par = J.shape
    if n_err > n_par:
        raise ConfigError(f"J is {n_err}x{n_par}: more errors than parameters, no right inverse exists")
    Js = (J / error_scales[:, None]) * param_scales[None, :]
    if kind == "inverse":
        Cs = np.linalg.inv(Js) if n_err == n_par else Js.T @ np.linalg.inv(Js @ Js.T)
    elif kind == "tsvd":
        U, s, Vt = np.linalg.svd(Js, full_matrices=False)
        keep = s > tsvd_rtol * s[0]
        Cs = (Vt[keep].T / s[keep]) @ U[:, keep].T
    elif kind == "damped":
        U, s, Vt = np.linalg.svd(Js, full_matrices=False)
        lam2 = (damping * s[0]) ** 2
        Cs = (Vt.T * (s / (s**2 + lam2))) @ U.T
    else:
        raise ConfigError(f"kind = {kind!r}: allowed 'inverse', 'tsvd', 'damped'")
    return (Cs * param_scales[:, None]) / error_scales[None, :]
