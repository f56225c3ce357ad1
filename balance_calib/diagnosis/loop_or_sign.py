"""Hysteresis or sign asymmetry on a component: the direction contrast decides.

Both families fit a residual that differs between points of one load magnitude, so the forward
selection lets them compete for it. The schedule separates them where it repeats a load reached
rising and falling (contrasts.py): a loop makes the two branches differ there; a sensitivity keyed
to the sign of the load cannot (the load, hence its sign, is the same). So each family keeps only
the components its contrast explains:

- hysteresis is not adopted on a component whose current residual shows no more direction
  contrast than noise does;
- bidirectional is not adopted on a component whose current residual does while hysteresis is
  offered there: the loop first, and a sign asymmetry beside it is found in a later round, once
  the loop is in the model and the contrast is gone.

Where the schedule offers too few pairs (on LMC6522 the forces, on B660H every component) the
contrast says nothing and the families compete as before.

A loop and a sign asymmetry on one bridge: the first adopted takes the share of the residual
the two have in common, and what is left for the second (the sign step once the loop is in)
can fall under the search's size gate (min_effect_pct_fs) while it is still significant at the
family's level and lowers the cross-validated σ (LMC6522 M_Y, a Preisach loop and a sensitivity
step of one floor each, seed 3000: |x| beside the loop p 1e-11, removing 0.0092 % FS of the gate's
0.01; the leftovers then found M_Y lacking fit, the loop explaining 62 % of it, and named
nothing). So on a component where one of the two is adopted and the model still lacks fit
against the repeatability, the other is judged without the size gate (`beside_its_partner`):
the structure there is established, and what it is made of is the question.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import scipy.stats

from .contrasts import EQUAL_LOAD, pairs_of_components

# A direction contrast counts as a loop with at least this many pairs, ratio mean(c²) / (2 σ²)
# at least LOOP_RATIO and its chi-square p-value below LOOP_P_VALUE; σ² is the smaller residual
# variance the two families leave. Measured (LMC6522 M_Y, 1x the floor, seeds 3000-3001): 7-11
# for Preisach, Bouc-Wen and Masing loops, 1.2-1.9 for a sign step, a negative-side curvature
# and clean campaigns.
# No loop only where the contrast is what noise gives (p-value at least NO_LOOP_P_VALUE): a loop
# at 0.5x the floor reaches ratios of 2.6-3.0 (Preisach, M_Y), significant but short of
# LOOP_RATIO, and is then left to the selection, not refused.
MIN_DIRECTION_PAIRS = 10
LOOP_RATIO = 3.0
LOOP_P_VALUE = 1e-3
NO_LOOP_P_VALUE = 0.01


def direction_pairs(corrected, orientation, direction, capacity) -> list[list[tuple[int, int]]]:
    """Per component, the index pairs (falling, rising) at equal applied load (contrasts.py).

    corrected: CorrectedData (loads and tare_loads (N, 6), N, N·m); orientation (N,);
    direction (N, 6) raw ±1 load history; capacity (6,) N, N·m.
    """
    applied = np.asarray(corrected.loads, float) - np.asarray(corrected.tare_loads, float)
    capacity = np.asarray(capacity, float)
    is_zero = np.all(np.abs(applied) <= EQUAL_LOAD * capacity, axis=1)
    found = pairs_of_components(
        applied, orientation, direction, is_zero, capacity, range(applied.shape[1])
    )
    return [direction_pairs for direction_pairs, _ in found]


def shows_loop(
    residual: np.ndarray, pairs: Sequence[tuple[int, int]], variance: float
) -> bool | None:
    """Does residual (N,) differ between the branches beyond variance (its units squared)?

    True: a loop (ratio >= LOOP_RATIO, p < LOOP_P_VALUE); False: no more than noise (p >=
    NO_LOOP_P_VALUE); None: in between, or fewer than MIN_DIRECTION_PAIRS pairs (the contrast
    then decides nothing).
    """
    if len(pairs) < MIN_DIRECTION_PAIRS or not variance > 0:
        return None
    index = np.asarray(pairs, int)
    values = residual[index[:, 0]] - residual[index[:, 1]]
    ratio = float(np.mean(values**2) / (2.0 * variance))
    p_value = float(scipy.stats.chi2.sf(len(values) * ratio, len(values)))
    if ratio >= LOOP_RATIO and p_value < LOOP_P_VALUE:
        return True
    return False if p_value >= NO_LOOP_P_VALUE else None


def components_to_drop(
    loop_residuals: dict,
    sign_residuals: dict,
    current: Sequence[np.ndarray],
    pairs: Sequence[Sequence[tuple[int, int]]],
) -> tuple[set[int], set[int]]:
    """(components hysteresis drops, components bidirectional drops).

    loop_residuals / sign_residuals: component index -> (N,) residual after that family's terms
    (the components each family passed on); current: per component (N,) residual before.
    """
    loop_drop, sign_drop = set(), set()
    for k, after in loop_residuals.items():
        fitted = [after] + ([sign_residuals[k]] if k in sign_residuals else [])
        verdict = shows_loop(
            np.asarray(current[k], float),
            pairs[k],
            min(float(np.mean(np.square(r))) for r in fitted),
        )
        if verdict is True and k in sign_residuals:
            sign_drop.add(k)
        elif verdict is False:
            loop_drop.add(k)
    return loop_drop, sign_drop


PARTNERS = {'hysteresis': 'bidirectional', 'bidirectional': 'hysteresis'}


def beside_its_partner(family: str, effects, fits, fitted_well) -> frozenset[int]:
    """Components on which `family` is judged without the search's size gate: those where its
    partner (hysteresis for bidirectional, and the other way round) is adopted and the model still
    lacks fit against the repeatability (see the module docstring).

    effects: the search's adopted entries ({'candidate': _Candidate, ...}); fits: per component
    the current fit; fitted_well(k, fit): False where component k lacks fit
    (search._fitted_well).
    """
    partner = PARTNERS.get(family)
    if partner is None:
        return frozenset()
    return frozenset(
        k
        for entry in effects
        if entry['candidate'].family == partner
        for k in entry['candidate'].components
        if not fitted_well(k, fits[k])
    )
