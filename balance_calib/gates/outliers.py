"""The one outlier rule of the acceptance gates, for bag campaigns and tables alike.

interfaces.md, gate `outliers`: no load point whose loads disagree with its outputs (a weight,
unit or typing error, a misplaced marker, a clipped point); TM-663 §6 judges a calibration by its
residuals, and a point shows its own error in its leave-one-out residual (outlier_statistic.py).

The rule. On each component a point is flagged when its standardised leave-one-out residual is
beyond max(k robust σ, floor) or is not finite: k `outlier_robust_sigmas` (7), floor
`outlier_floor_pct_fs` (0.05 % of capacity), σ 1.4826 MAD over the loaded points (zero points fit
their tares almost exactly and would shrink it). A flagged point is not an outlier when structure
explains it (gates judge after the diagnosis; Diagnosis.residuals_named):

    named      it is within the threshold after the effect named on its component (adopted, or
               named as fitting part of the structure): its leave-one-out residual with that
               effect's terms (diagnosis/coherence.py's CampaignStructure.residuals_named)
    campaign   the campaign's structure, fitted on the other points, predicts it within the
               threshold, on a component where the diagnosis found something (coherence.py)
    alike      more than STRUCTURE_MIN_POINTS points of one component are flagged, and it is not
               beyond DOMINANCE times their median: a shape the model lacks (a low-load knee on
               every series of a load) moves many points alike, a typed weight stands out of the
               points it drags along with it

What differs between the callers is what they pass, not the rule: a refit passes the diagnosis's
structure (named, campaign); a table calibration judges the residuals of the model it adopts
after the loop is closed on it (an adopted effect's points are judged with its terms), passes
no structure, asks for `alike`, and for `tail_quantile`: its points mix load levels and zero
brackets of unequal scatter, so its σ is at least the 90 % point of |residual| / 1.6449 too
(outlier_statistic.robust_sigma). `alike` and `tail_quantile` stay the tables' alone because on
bags they would change the robust σ every refit reports and excuse faults a refit refuses today.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .limits import DEFAULT_OUTLIER_FLOOR_PCT_FS, DEFAULT_OUTLIER_ROBUST_SIGMAS
from .outlier_statistic import robust_sigma, standardized_press, worst_first

STRUCTURE_MIN_POINTS = 3  # more points of one load beyond the outlier limit than this,
DOMINANCE = 4.0  # and only those this far beyond the median of them are outliers


@dataclass(frozen=True)
class OutlierRule:
    """The rule's limits and the two choices a caller makes (see the module's docstring)."""

    robust_sigmas: float = DEFAULT_OUTLIER_ROBUST_SIGMAS
    floor_pct: float = DEFAULT_OUTLIER_FLOOR_PCT_FS
    tail_quantile: bool = False  # σ at least the 90 % point of |residual| / 1.6449
    alike: bool = False  # many points of a component flagged alike are structure


@dataclass(frozen=True)
class JudgedResiduals:
    """What the rule judges: residuals and leave-one-out residuals (N, k) in the capacity's unit,
    capacity (k,), the loaded points (N,) bool (the robust σ's basis) and the k symbols.
    """

    symbols: Sequence[str]
    residuals: np.ndarray
    press: np.ndarray
    capacity: np.ndarray
    loaded: np.ndarray


@dataclass(frozen=True)
class OutlierVerdict:
    """The rule's result, all in % of capacity: (N, k) press_pct, standardized, flagged (outliers
    left), explained (by named or campaign structure); (k,) robust σ and threshold; alike:
    symbol -> rows excused as alike; rows (M,) the outliers worst first, worst (M,) the component
    each is worst in.
    """

    press_pct: np.ndarray
    standardized: np.ndarray
    robust: np.ndarray
    threshold: np.ndarray
    flagged: np.ndarray
    explained: np.ndarray
    rows: np.ndarray
    worst: np.ndarray
    alike: dict = field(default_factory=dict)


def judge_outliers(data: JudgedResiduals, rule: OutlierRule, structure=None) -> OutlierVerdict:
    """The one outlier rule. structure: diagnosis.coherence.CampaignStructure or None."""
    press_pct, standardized = standardized_press(data.residuals, data.press, data.capacity)
    robust = robust_sigma(standardized, data.loaded, tail_quantile=rule.tail_quantile)
    threshold = np.maximum(rule.robust_sigmas * robust, rule.floor_pct)
    flagged = (np.abs(standardized) > threshold) | ~np.isfinite(standardized)
    explained = _explained_by_structure(data, standardized, flagged, threshold, structure)
    flagged &= ~explained
    alike = {}
    if rule.alike:
        for k, symbol in enumerate(data.symbols):
            off = flagged[:, k] & np.isfinite(standardized[:, k])
            if np.count_nonzero(off) > STRUCTURE_MIN_POINTS:
                size = np.abs(standardized[:, k])
                same = off & (size <= DOMINANCE * np.median(size[off]))
                alike[symbol] = np.flatnonzero(same)
                flagged[same, k] = False
    rows, worst = worst_first(flagged, standardized, threshold)
    return OutlierVerdict(
        press_pct, standardized, robust, threshold, flagged, explained, rows, worst, alike
    )


def _explained_by_structure(data, standardized, flagged, threshold, structure) -> np.ndarray:
    """(N, k) flagged residuals explained on components where the diagnosis adopted an effect
    or left structure unexplained: within the threshold once judged after the effect named there
    (its leave-one-out residual with the named family's terms, diagnosis/coherence.py), or
    predicted within it by the campaign's structure from the other points.
    """
    explained = np.zeros_like(flagged)
    if structure is None:
        return explained
    from ..diagnosis.coherence import fit_structure

    named = _after_named(data, structure, standardized)
    for k, component in enumerate(data.symbols):
        if component not in structure.covered or not np.any(flagged[:, k]):
            continue
        within = np.abs(named[:, k]) <= threshold[k]
        fit = fit_structure(standardized[:, k], structure.basis, k, flagged[:, k])
        if fit.explains:
            within |= np.abs(fit.out_of_sample) <= threshold[k]
        explained[:, k] = flagged[:, k] & within
    return explained


def _after_named(data, structure, standardized) -> np.ndarray:
    """(N, k) standardised leave-one-out residuals after the effects named on each component
    (structure.residuals_named), NaN where there are none or on a component with nothing named.
    """
    named = np.full_like(standardized, np.nan)
    residuals, press = structure.residuals_named, structure.press_named
    if residuals is None or press is None or np.shape(residuals) != np.shape(standardized):
        return named
    _, after = standardized_press(
        np.asarray(residuals, float), np.asarray(press, float), data.capacity
    )
    for k, component in enumerate(data.symbols):
        if component in structure.named:
            named[:, k] = after[:, k]
    return named
