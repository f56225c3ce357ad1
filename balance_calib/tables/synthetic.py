"""Calibration tables with a known truth, for tests and benchmarks (no laboratory data ships here).

Two directions of truth:
- `iterative_truth`: outputs = A · g(total loads) with R-091's 96 terms, noise on the outputs;
- `direct_truth`: loads = C · x(outputs) with TM-663's cubic terms, noise on the loads.
Schedules: single-load sweeps and two-load combinations in all sign quadrants (the support a
TM-663 / R-091 schedule gives), one load series each with its own tare; and, for checks outside the
support, points with all six loads at once.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

from ..model.balance_model import BalanceModel
from ..model.inverse import outputs_for_loads
from ..model.r091 import IterativeModel, r091_terms, tm663_cubic_terms
from .balfit_reader import CalibrationTable
from .units import known_unit

LOADS = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')
OUTPUTS = ('FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV')
UNITS = ('lbs', 'lbs', 'lbs', 'in-lbs', 'in-lbs', 'in-lbs')
CAPACITY_FILE = np.array([100.0, 200.0, 800.0, 300.0, 600.0, 250.0])  # in UNITS
RATED_OUTPUT_MV = np.array([2.0, 2.5, 3.0, 2.2, 2.8, 2.4])


@dataclass(frozen=True)
class Schedule:
    applied_si: np.ndarray  # (N, 6)
    series: np.ndarray  # (N,)


def capacity_si() -> np.ndarray:
    return CAPACITY_FILE * np.array([known_unit(u)[0] for u in UNITS])


def support_schedule(
    rng, points_single: int = 21, points_pair: int = 40, first_series: int = 1, repeats: int = 1
) -> Schedule:
    """Single-load sweeps (one series per load) and random two-load combinations (one series per
    pair), loads within ±capacity; `repeats` copies of the whole schedule, each with its own
    series.
    """
    cap = capacity_si()
    rows, series = [], []
    label = first_series
    for _ in range(repeats):
        for v in range(6):
            block = np.zeros((points_single, 6))
            block[:, v] = np.linspace(-1, 1, points_single) * cap[v]
            rows.append(block)
            series += [label] * points_single
            label += 1
        for v, w in combinations(range(6), 2):
            block = np.zeros((points_pair, 6))
            block[:, v] = rng.uniform(-1, 1, points_pair) * cap[v]
            block[:, w] = rng.uniform(-1, 1, points_pair) * cap[w]
            rows.append(block)
            series += [label] * points_pair
            label += 1
    return Schedule(np.vstack(rows), np.array(series))


def six_at_once(rng, points: int, fraction: float = 0.6) -> np.ndarray:
    """(N, 6) SI: all six loads at once, each uniform in ±fraction x capacity: outside a
    schedule's support.
    """
    return rng.uniform(-fraction, fraction, (points, 6)) * capacity_si()


def iterative_truth(rng, nonlinear_fraction: float = 0.004) -> IterativeModel:
    """R-091 96-term truth: outputs (mV) from loads (N, N·m). Each non-linear term contributes up
    to `nonlinear_fraction` of rated output at capacity; the linear part has 2 % interactions.
    """
    terms = r091_terms(LOADS)
    cap = capacity_si()
    coefficients = np.zeros((6, len(terms)))
    for j, term in enumerate(terms):
        size = np.prod([cap[LOADS.index(f.variable)] ** f.power for f in term.factors])
        if term.degree == 1 and not term.factors[0].absolute:
            v = LOADS.index(term.factors[0].variable)
            column = rng.uniform(-0.02, 0.02, 6) * RATED_OUTPUT_MV
            column[v] = RATED_OUTPUT_MV[v]
            coefficients[:, j] = column / cap[v]
        else:
            coefficients[:, j] = (
                rng.uniform(-1, 1, 6) * nonlinear_fraction * RATED_OUTPUT_MV / size
            )
    return IterativeModel('truth', terms, coefficients, LOADS, OUTPUTS, {'capacity': cap.tolist()})


def direct_truth(rng, nonlinear_fraction: float = 0.006) -> BalanceModel:
    """TM-663 cubic truth (no constant): loads (N, N·m) from outputs (mV)."""
    terms = tm663_cubic_terms(OUTPUTS)
    cap = capacity_si()
    coefficients = np.zeros((6, len(terms)))
    for j, term in enumerate(terms):
        size = np.prod(
            [RATED_OUTPUT_MV[OUTPUTS.index(f.variable)] ** f.power for f in term.factors]
        )
        if term.degree == 1:
            v = OUTPUTS.index(term.factors[0].variable)
            column = rng.uniform(-0.02, 0.02, 6) * cap
            column[v] = cap[v]
            coefficients[:, j] = column / RATED_OUTPUT_MV[v]
        else:
            coefficients[:, j] = rng.uniform(-1, 1, 6) * nonlinear_fraction * cap / size
    return BalanceModel('truth', terms, coefficients, LOADS, OUTPUTS)


def tares_for(rng, series_labels, fraction: float = 0.03) -> dict[int, np.ndarray]:
    return {int(s): rng.uniform(-fraction, fraction, 6) * capacity_si() for s in series_labels}


def make_table(
    applied_si,
    outputs_mv,
    series,
    *,
    name: str = 'synthetic',
    natural_zero_mv=None,
    zero_set: str = 'Z1',
    point_prefix: str = 'P',
) -> CalibrationTable:
    """A CalibrationTable in lbs / in-lbs and mV; outputs get the natural zero added back."""
    factor = np.array([known_unit(u)[0] for u in UNITS])
    zero = np.zeros(6) if natural_zero_mv is None else np.asarray(natural_zero_mv, float)
    roll = np.array([0.0, 90.0, 180.0, 270.0])
    gravity_pattern = np.outer(np.cos(np.radians(roll)).round(12), np.full(6, 0.01)) + np.outer(
        np.sin(np.radians(roll)).round(12), np.full(6, -0.02)
    )
    n = len(applied_si)
    return CalibrationTable(
        name,
        'DATA_FOR_ITERATIVE_REGRESSION_ANALYSIS',
        name,
        'generated with a known truth',
        LOADS,
        OUTPUTS,
        UNITS,
        ('mV',) * 6,
        CAPACITY_FILE.copy(),
        RATED_OUTPUT_MV.copy(),
        tuple(f'NZ-{i + 1}' for i in range(4)),
        (zero_set,) * 4,
        roll,
        zero[None, :] + gravity_pattern,
        tuple(f'{point_prefix}-{i + 1:05d}' for i in range(n)),
        np.asarray(series, int),
        (zero_set,) * n,
        np.asarray(applied_si, float) / factor,
        np.asarray(outputs_mv, float) + zero[None, :],
    )


def iterative_campaign(
    rng, truth: IterativeModel, schedule: Schedule, tares: dict, noise_mv: float
):
    """(applied SI, outputs mV) with outputs = truth(applied + tare) + N(0, noise_mv)."""
    totals = schedule.applied_si + np.array([tares[int(s)] for s in schedule.series])
    outputs = truth.outputs(totals) + rng.normal(0, noise_mv, (len(totals), 6))
    return schedule.applied_si, outputs


def direct_campaign(rng, truth: BalanceModel, schedule: Schedule, tares: dict, noise_load_si):
    """(applied SI, outputs mV) with applied = truth(V) - tare + N(0, noise) (noise on the
    loads).
    """
    totals = schedule.applied_si + np.array([tares[int(s)] for s in schedule.series])
    outputs = outputs_for_loads(truth, totals)
    applied = schedule.applied_si + rng.normal(0, 1, totals.shape) * np.asarray(noise_load_si)
    return applied, outputs
