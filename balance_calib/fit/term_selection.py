"""Per-term statistics that AIAA R-091 users look at when they choose a math model.

For a linear least-squares fit Y ≈ Z·B (shared design Z (N, q), targets Y (N, k)):
- VIF_j: variance inflation factor (uncentred: the fits have no constant), 1/(1 - R_j²) with R_j²
of
  column j regressed on the other columns; = [(ZᵀZ)⁻¹]_jj · z_jᵀz_j. Above 10 the term is nearly a
  combination of the others.
- t and p of each coefficient: t = b / se(b) with N - q degrees of freedom (two-sided p).
- PRESS ratio: PRESS of the model without term j over PRESS of the full model, per target. Computed
  without refits: H = H₋ⱼ + q_j q_jᵀ with q_j the normalised j-th column of Z(ZᵀZ)⁻¹ (orthogonal to
  all other columns), so the residuals and leverages without term j follow in closed form.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.stats

from ..model.leverage import leverage_of_rows


@dataclass(frozen=True)
class TermStatistics:
    terms: tuple[str, ...]
    targets: tuple[str, ...]
    vif: np.ndarray  # (p,)
    t_value: np.ndarray  # (p, k)
    p_value: np.ndarray  # (p, k)
    press_ratio: np.ndarray  # (p, k): PRESS without the term / PRESS with it (> 1: the term helps)

    def to_report(self, limit: int | None = None) -> list[dict[str, object]]:
        rows = []
        for j, term in enumerate(self.terms):
            rows.append(
                {
                    'term': term,
                    'vif': float(f'{self.vif[j]:.4g}'),
                    'p_value': {
                        t: float(f'{p:.3g}') for t, p in zip(self.targets, self.p_value[j])
                    },
                    'press_ratio': {
                        t: round(float(r), 5) for t, r in zip(self.targets, self.press_ratio[j])
                    },
                    'significant': bool(np.any(self.p_value[j] < 0.01)),
                    'helps_press': bool(np.any(self.press_ratio[j] > 1.0)),
                }
            )
        return rows[:limit] if limit else rows

    def weak_terms(self) -> list[str]:
        """Terms insignificant on every target (p >= 0.01) whose removal lowers PRESS
        everywhere.
        """
        return [
            t
            for j, t in enumerate(self.terms)
            if np.all(self.p_value[j] >= 0.01) and np.all(self.press_ratio[j] <= 1.0)
        ]


def term_statistics(
    design: np.ndarray,
    targets: np.ndarray,
    coefficients: np.ndarray,
    covariance_unscaled: np.ndarray,
    n_terms: int,
    term_names: Sequence[str],
    target_names: Sequence[str],
) -> TermStatistics:
    """Statistics of the first `n_terms` columns of `design` (the rest are nuisance columns:
    tares).

    coefficients (q, k), covariance_unscaled (q, q) = (ZᵀZ)⁻¹.
    """
    n, q = design.shape
    residuals = targets - design @ coefficients
    dof = max(n - q, 1)
    sigma2 = (residuals**2).sum(axis=0) / dof
    diag = np.diag(covariance_unscaled)[:n_terms]
    vif = diag * (design[:, :n_terms] ** 2).sum(axis=0)
    se = np.sqrt(np.outer(diag, sigma2))
    with np.errstate(divide='ignore', invalid='ignore'):
        t_value = np.where(se > 0, coefficients[:n_terms] / se, 0.0)
    p_value = 2.0 * scipy.stats.t.sf(np.abs(t_value), dof)

    pinv_columns = design @ covariance_unscaled[:, :n_terms]  # (N, p): Z (ZᵀZ)⁻¹ e_j
    q_cols = pinv_columns / np.maximum(np.linalg.norm(pinv_columns, axis=0), 1e-300)
    h = np.minimum(leverage_of_rows(design, covariance_unscaled), 1 - 1e-12)
    press_full = ((residuals / (1 - h)[:, None]) ** 2).sum(axis=0)
    projection = q_cols.T @ targets  # (p, k)
    press_without = np.empty((n_terms, targets.shape[1]))
    for j in range(n_terms):  # p vector operations of (N, k); no refits
        h_without = np.minimum(h - q_cols[:, j] ** 2, 1 - 1e-12)
        e_without = residuals + np.outer(q_cols[:, j], projection[j])
        press_without[j] = ((e_without / (1 - h_without)[:, None]) ** 2).sum(axis=0)
    return TermStatistics(
        tuple(term_names),
        tuple(target_names),
        vif,
        t_value,
        p_value,
        press_without / np.maximum(press_full, 1e-300),
    )


def elimination_step(
    design: np.ndarray,
    targets: np.ndarray,
    n_terms: int,
    term_names: Sequence[str],
    target_names: Sequence[str],
    *,
    full_rank_only: bool = False,
) -> TermStatistics | None:
    """One step of backward elimination: the least-squares fit of targets (N, k) on design (N, q)
    by SVD of the norm-scaled columns (an all-zero column keeps scale 1), and the statistics of
    its first `n_terms` columns (`term_statistics`). With `full_rank_only`, None when the scaled
    design is rank deficient (smallest singular value ≤ 1e-12 of the largest): no term's PRESS
    is then defined.
    """
    scales = np.linalg.norm(design, axis=0)
    scales[scales == 0] = 1.0
    u, singular, vt = np.linalg.svd(design / scales, full_matrices=False)
    if full_rank_only and singular[-1] <= singular[0] * 1e-12:
        return None
    v_scaled = vt.T / singular
    covariance = (v_scaled @ v_scaled.T) / np.outer(scales, scales)
    coefficients = (v_scaled @ (u.T @ targets)) / scales[:, None]
    return term_statistics(
        design, targets, coefficients, covariance, n_terms, term_names, target_names
    )


@dataclass(frozen=True)
class Selection:
    kept: tuple[str, ...]
    removed: tuple[str, ...]
    reasons: tuple[str, ...]  # one line per removed term, in removal order


def backward_elimination(
    design: np.ndarray,
    targets: np.ndarray,
    n_terms: int,
    term_names: Sequence[str],
    target_names: Sequence[str],
    keep: Sequence[str] = (),
    alpha: float = 0.01,
) -> Selection:
    """R-091-style math-model search by PRESS: repeatedly drop the term whose removal lowers PRESS
    most (mean over targets of log(PRESS without / PRESS with) < 0) among terms significant on no
    target (p >= alpha); stop when no such term is left. Columns after `n_terms` (tares) are never
    dropped; nor are the names in `keep` (e.g. the linear terms the Newton inverse starts from).
    """
    names = list(term_names)
    columns = list(range(n_terms))
    removed, reasons = [], []
    nuisance = design[:, n_terms:]
    while len(columns) > 1:
        current = np.hstack([design[:, columns], nuisance])
        stats = elimination_step(
            current, targets, len(columns), [names[c] for c in columns], target_names
        )
        assert stats is not None  # only full_rank_only returns None
        score = np.mean(np.log(np.maximum(stats.press_ratio, 1e-300)), axis=1)
        candidates = [
            i
            for i in range(len(columns))
            if names[columns[i]] not in keep and np.all(stats.p_value[i] >= alpha) and score[i] < 0
        ]
        if not candidates:
            break
        worst = min(candidates, key=lambda i: score[i])
        removed.append(names[columns[worst]])
        reasons.append(
            f'{names[columns[worst]]}: p ≥ {alpha} on every target (min '
            f'{stats.p_value[worst].min():.2g}), PRESS {100 * (np.exp(score[worst]) - 1):+.2f} '
            f'% without it, VIF {stats.vif[worst]:.3g}'
        )
        del columns[worst]
    return Selection(tuple(names[c] for c in columns), tuple(removed), tuple(reasons))
