"""Candidate explanations of calibration residuals: one family of terms per physical effect.

Every family is a list of term *groups* (a group is added or left out as a whole: a sine and a
cosine of one frequency, otherwise single terms) over named variables, so the adopted fit is an
ordinary `BalanceModel` whose extra variables carry these names:

    temperature    dT, dT^2, dT*FXV ... dT*MZV      dT = T - T_ref, T_ref the campaign mean (K)
    zero_drift     drift_sin_m, drift_cos_m         Fourier basis in time (nuisance, not live)
    hysteresis     dir_FX ... dir_MZ, dir_FX*FXV ... dir_X = +1 rising / -1 falling load on X
    bidirectional  |FXV| ..., FXV*|FXV| ...          AIAA R-091 sign-dependent terms
    cross_terms    FXV^2*FZV, FXV*FYV*FZV, ...       monomials up to degree 3 the base model lacks
    tare           (no terms: body weight and CG refitted, see tare_refit.py)

Variables that offset the outputs (dir_X, the drift basis) are *referred to the zero points*
exactly as the bridge outputs are (TM-663 §5(4)): value minus its interpolation between the
bracketing zero points. Live, the wind-off tare does the same referring: a hysteresis term c·dir_X
read with the raw ±1 and the tare offset subtracted gives c·(dir_X - dir_X at tare).
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations_with_replacement
from typing import Mapping, Sequence

import numpy as np

from ..model.terms import Term
from ..zero_points import subtract_zero_points

EFFECT_NAMES = ('temperature', 'zero_drift', 'hysteresis', 'bidirectional', 'cross_terms', 'tare')
# Families whose terms are fitted at calibration but not applied live.
NUISANCE_EFFECTS = ('zero_drift',)


@dataclass(frozen=True)
class CandidateFamily:
    """The terms one physical effect may add to a component."""

    name: str
    groups: tuple[tuple[str, ...], ...]     # canonical term names, in groups added as a whole
    max_groups: int                         # forward selection adds at most this many per component
    labels: Mapping[tuple[str, ...], str]   # what a group means, for the evidence line

    @property
    def nuisance(self) -> bool:
        return self.name in NUISANCE_EFFECTS

    @property
    def terms(self) -> tuple[str, ...]:
        return tuple(t for g in self.groups for t in g)

    def label(self, groups: Sequence[tuple[str, ...]]) -> str:
        return ' + '.join(self.labels.get(tuple(g), '+'.join(g)) for g in groups)


def canonical(name: str) -> str:
    return Term.parse(name).name


def _single(name: str, terms: Sequence[str], max_groups: int) -> CandidateFamily:
    names = tuple(canonical(t) for t in terms)
    return CandidateFamily(name, tuple((t,) for t in names), max_groups, {})


def temperature_family(outputs: Sequence[str]) -> CandidateFamily:
    return _single('temperature', ['dT', 'dT^2'] + [f'dT*{v}' for v in outputs], 3)


def hysteresis_family(components: Sequence[str], outputs: Sequence[str]) -> CandidateFamily:
    return _single('hysteresis', [f'dir_{c}' for c in components]
                   + [f'dir_{c}*{v}' for c, v in zip(components, outputs)], 3)


def bidirectional_family(outputs: Sequence[str]) -> CandidateFamily:
    return _single('bidirectional', [f'|{v}|' for v in outputs] + [f'{v}*|{v}|' for v in outputs], 3)


def cross_terms_family(outputs: Sequence[str], base_terms: Sequence[str], max_groups: int = 4) -> CandidateFamily:
    """All monomials of degree 1-3 in the outputs that the base model does not have."""
    base = {canonical(t) for t in base_terms}
    names = []
    for degree in (1, 2, 3):
        for combo in combinations_with_replacement(outputs, degree):
            name = canonical('*'.join(combo))
            if name not in base:
                names.append(name)
    return _single('cross_terms', names, max_groups)


def drift_family(frequencies_hz: np.ndarray, max_groups: int = 8) -> CandidateFamily:
    groups, labels = [], {}
    for m, f in enumerate(frequencies_hz, start=1):
        group = (f'drift_sin_{m}', f'drift_cos_{m}')
        groups.append(group)
        labels[group] = f'{1.0 / f:.0f} s'
    return CandidateFamily('zero_drift', tuple(groups), max_groups, labels)


# --- the variables ----------------------------------------------------------------------------
def refer_to_zero_points(values, times_s, is_zero_point, orientation) -> np.ndarray:
    """values (N,) or (N, m) minus their interpolation between the bracketing zero points, §5(4)."""
    values = np.asarray(values, dtype=float)
    column = values.ndim == 1
    referred = subtract_zero_points(times_s, values[:, None] if column else values, is_zero_point,
                                    orientation).zeroed_outputs_mv
    return referred[:, 0] if column else referred


def load_directions(loads, times_s, capacity) -> np.ndarray:
    """(N, n) +1 where the load on a component last rose, -1 where it last fell, in time order.

    Starts rising, as the simulated balance and the live LoadHistory do; a change smaller than
    1e-9 of capacity (the same load hung again) keeps the previous direction.
    """
    loads = np.atleast_2d(np.asarray(loads, dtype=float))
    order = np.argsort(np.asarray(times_s, dtype=float), kind='stable')
    steps = np.diff(loads[order], axis=0)
    sign = np.where(np.abs(steps) > 1e-9 * np.asarray(capacity, float), np.sign(steps), 0.0)
    sign = np.vstack([np.ones((1, loads.shape[1])), sign])
    rows = np.arange(len(sign))[:, None] * np.ones((1, loads.shape[1]), dtype=int)
    last = np.maximum.accumulate(np.where(sign != 0, rows, 0), axis=0)     # forward fill
    direction_sorted = np.take_along_axis(sign, last, axis=0)
    direction = np.empty_like(direction_sorted)
    direction[order] = direction_sorted
    return direction


def drift_frequencies(times_s, oversampling: float = 2.0) -> np.ndarray:
    """Frequency grid (Hz) from one cycle per campaign to the Nyquist frequency of the points."""
    times = np.sort(np.asarray(times_s, dtype=float))
    span = float(times[-1] - times[0])
    spacing = float(np.median(np.diff(times))) if len(times) > 1 else span
    if span <= 0 or spacing <= 0:
        return np.zeros(0)
    step = 1.0 / (oversampling * span)
    return np.arange(1, int(np.floor((0.5 / spacing) / step)) + 1) * step


def drift_variables(times_s, frequencies_hz, is_zero_point, orientation) -> dict[str, np.ndarray]:
    """The Fourier basis in time, referred to the zero points: only what they do not follow."""
    times = np.asarray(times_s, dtype=float)
    phase = 2 * np.pi * (times - times.min())[:, None] * np.asarray(frequencies_hz)[None, :]
    basis = np.hstack([np.sin(phase), np.cos(phase)])
    referred = refer_to_zero_points(basis, times, is_zero_point, orientation)
    n = len(frequencies_hz)
    variables = {}
    for m in range(n):
        variables[f'drift_sin_{m + 1}'] = referred[:, m]
        variables[f'drift_cos_{m + 1}'] = referred[:, n + m]
    return variables


def without_base_terms(family: CandidateFamily, base_terms: Sequence[str]) -> CandidateFamily:
    """The family without the groups already in the base model."""
    base = {canonical(t) for t in base_terms}
    groups = tuple(g for g in family.groups if not set(g) & base)
    return CandidateFamily(family.name, groups, family.max_groups, family.labels)


def direction_variables(loads, times_s, capacity, components, is_zero_point, orientation):
    """dir_X variables referred to the zero points, and the raw ±1 directions (N, n)."""
    raw = load_directions(loads, times_s, capacity)
    referred = refer_to_zero_points(raw, times_s, is_zero_point, orientation)
    return {f'dir_{c}': referred[:, k] for k, c in enumerate(components)}, raw

