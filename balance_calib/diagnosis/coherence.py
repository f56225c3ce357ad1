"""Is a point that disagrees with the adopted model wrong on its own, or part of a structure?

The outliers gate (gates/outliers.py) flags points whose loads disagree with their outputs beyond
k robust σ of the adopted model's leave-one-out residuals. A weight typo, a load recorded in the
wrong unit or a marker on the wrong point is wrong *on its own*: its neighbours in load, load
history and time do not share its residual. An effect the model lacks (a hysteresis loop of a
shape no family holds, a sign asymmetry, a leftover the diagnosis reported as `unexplained`)
moves every point of the same history the same way.

First, a flagged point on a component where the leftovers found an effect fitting only part of
the structure (named in `unexplained` as partly fitted, its terms not adopted) is judged on the
residuals after that effect: the adopted model with the named family's terms refitted on that
component, leave-one-out (Diagnosis.residuals_named). A sign step on the forces of B660H beside
loops on every bridge (one floor each) leaves the full-load point of F_Z at 9 robust σ of the
adopted model's leave-one-out residuals; with the |F_ZV| the leftovers named there it sits at
3.5, within the gate's 7, and the gate's own robust σ falls (0.093 -> 0.074 % FS): the point
disagrees with the model by the effect, not by its weight. A weight typo stays: the named terms
are fitted on the other points, and a point's leave-one-out residual does not see its own load.

Then each flagged component's residual is regressed on a broad, physics-neutral basis of what a
point's structure can follow (`structure_basis`: the load history of every component, as load
directions, distances from the last turning point and play operators of six widths on the
outputs, the load magnitudes, and slow time), and the flagged point is predicted *from the other
points alone*: the basis is fitted to the points not flagged and predicts the flagged ones. A
point whose own residual that prediction leaves within the gate's threshold is explained by the
structure; a point whose residual nothing else in the campaign shares keeps it (the fit never saw
it, and flagged points cannot explain one another). The structure must also be real without the
flagged points: the basis's partial F-test on the others, at level `alpha`.

The basis is built from the *fitted* loads (applied minus residual), not the applied ones: a
column of the target would fit part of a typo. Only components on which the diagnosis adopted an
effect or reported `unexplained` structure are examined (`diagnosis_structure`): elsewhere the
residuals are at the repeatability and a flagged point has nothing to belong to.

Limit (measured on test/diagnosis_physics.py's ratcheting joint on every bridge of LMC6522): at
0.5 % of rated output at its widest every flagged point is explained; at 1 % one or two points
per campaign are predicted too loosely by the others and stay refused.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.stats

from ..fit.svd import minimum_norm_solve
from .candidates import (
    absolute_load_variables,
    BridgeOutputs,
    direction_variables,
    play_lag,
)

EXTRA_PLAY_WIDTHS = (0.05, 0.2, 0.6)  # x rated output, besides candidates.PLAY_WIDTHS
ALPHA_STRUCTURE = 1e-3  # the basis's F-test on the points not flagged, per component


@dataclass(frozen=True)
class StructureFit:
    """The flagged points of one component predicted from the other points' structure."""

    component: int
    out_of_sample: np.ndarray  # (N,) residual minus the prediction from the other points
    p_value: float  # F-test of the basis on the other points' residual
    explains: bool  # p < alpha


def structure_basis(
    fitted_loads: np.ndarray,
    outputs: BridgeOutputs,
    times_s: np.ndarray,
    is_zero_point: np.ndarray,
    orientation: np.ndarray,
    capacity: np.ndarray,
    components,
) -> np.ndarray:
    """(N, m) columns a structure across the campaign can follow (see the module docstring).

    fitted_loads (N, 6) N, N·m; outputs: (N, 6) mV, their names and (6,) rated outputs; times_s
    (N,) s; capacity (6,). Columns are centred and scaled to unit RMS; constant ones dropped.
    """
    outputs_mv, rated_outputs_mv = outputs.values, outputs.rated_mv
    variables, _ = direction_variables(
        fitted_loads,
        times_s,
        capacity,
        components,
        is_zero_point,
        orientation,
        outputs=outputs,
        fitted_loads=fitted_loads,
    )
    columns = list(variables.values())
    columns += [  # |x| only: the basis as it was before x|x|, x²|x| joined the family
        v
        for name, v in absolute_load_variables(fitted_loads, capacity, components).items()
        if name.startswith('absload_')
    ]
    for width in EXTRA_PLAY_WIDTHS:  # a loop of many hysterons: more widths than the family's
        half = width * np.asarray(rated_outputs_mv, float)
        columns += list(play_lag(outputs_mv, times_s, half).T)
    t = np.asarray(times_s, float)
    span = max(float(t.max() - t.min()), 1e-9)
    u = 2.0 * (t - t.min()) / span - 1.0
    columns += [u, 1.5 * u**2 - 0.5, 2.5 * u**3 - 1.5 * u]  # Legendre P1-P3
    basis = np.column_stack(columns)
    basis = basis - basis.mean(axis=0)
    scale = np.sqrt(np.mean(basis**2, axis=0))
    keep = scale > 1e-12
    return basis[:, keep] / scale[keep]


def fit_structure(
    residual: np.ndarray,
    basis: np.ndarray,
    k: int,
    flagged: np.ndarray,
    alpha: float = ALPHA_STRUCTURE,
) -> StructureFit:
    """Fit one component's (standardized) residual (N,) on a constant and the basis (N, m) over the
    points not flagged, and predict the flagged ones (N,) bool from that fit.

    The structure must be there without the flagged points: partial F-test of the basis over the
    constant on the others, at level alpha. Returns residual - prediction (NaN where not finite).
    """
    residual = np.asarray(residual, float)
    x = np.column_stack([np.ones(len(residual)), basis])
    train = np.isfinite(residual) & ~np.asarray(flagged, bool)
    y = residual[train]
    coefficients, rank = minimum_norm_solve(x[train], y, rcond=1e-10)
    out = np.where(np.isfinite(residual), residual - x @ coefficients, np.nan)
    rss = float(np.sum((y - x[train] @ coefficients) ** 2))
    base_rss = float(np.sum((y - y.mean()) ** 2))
    extra, dof = int(rank) - 1, len(y) - int(rank)
    p_value = 1.0
    if extra > 0 and dof > 0 and rss > 0:
        f_value = ((base_rss - rss) / extra) / (rss / dof)
        p_value = float(scipy.stats.f.sf(f_value, extra, dof))
    return StructureFit(k, out, p_value, p_value < alpha)


@dataclass(frozen=True)
class CampaignStructure:
    """What the outliers gate may hold a flagged point's residual against."""

    basis: np.ndarray  # (N, m) structure_basis of the campaign
    covered: dict  # component -> the structure the diagnosis found there
    # (N, 6) residuals and leave-one-out residuals after the effects named on each component
    # (Diagnosis.residuals_named), or None
    residuals_named: np.ndarray | None = None
    press_named: np.ndarray | None = None
    named: dict = field(default_factory=dict)  # component -> the families named, not adopted


def diagnosis_structure(diagnosis, points, config) -> CampaignStructure | None:
    """The campaign's structure basis and, per component, what the diagnosis adopted or left
    `unexplained` there (only those components may have their flagged points explained).
    None when the diagnosis's points are not the gate's (another order or subset).
    """
    if diagnosis is None or not np.array_equal(
        np.asarray(diagnosis.point_labels), np.asarray(points.label)
    ):
        return None
    covered: dict[str, str] = {}
    named: dict[str, str] = {}
    for entry in diagnosis.unexplained:
        for c in entry.components:
            covered.setdefault(
                c,
                f'the structure the diagnosis left unexplained on {c} (it tracks {entry.tracks})',
            )
            if entry.partly_fitted_by:
                named.setdefault(c, ', '.join(entry.partly_fitted_by))
    for effect in diagnosis.effects:
        for c in effect.components:
            covered.setdefault(c, f'the {effect.name} effect adopted on {c}')
    fitted = np.asarray(diagnosis.corrected.loads, float) - np.asarray(
        diagnosis.residuals_after, float
    )
    basis = structure_basis(
        fitted,
        BridgeOutputs(
            diagnosis.corrected.bridge_outputs_mv, config.bridge_outputs, config.rated_output_mv
        ),
        points.times_s,
        points.is_zero_point,
        points.orientation,
        config.capacity,
        config.components,
    )
    return CampaignStructure(
        basis,
        covered,
        getattr(diagnosis, 'residuals_named', None),
        getattr(diagnosis, 'press_residuals_named', None),
        named,
    )
