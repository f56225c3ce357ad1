"""Candidate explanations of calibration residuals: one family of terms per physical effect.

Every family is a list of term *groups* (a group is added or left out as a whole: a sine and a
cosine of one frequency, otherwise single terms) over named variables, so the adopted fit is an
ordinary `BalanceModel` whose extra variables carry these names:

    temperature    dT, dT^2, dT*FXV, dT^2*FXV ...  dT = T - T_ref, T_ref the campaign mean (K):
                                                    zero, sensitivity and their dT² shapes
    zero_drift     drift_sin_m, drift_cos_m         Fourier basis in time (nuisance, not live)
    hysteresis     dir_X, dir_X*XV, dir_X*|XV|      dir_X = +1 rising / -1 falling load on X: a
                                                    constant loop, a slope loop, an offset loop
                                                    even in the output (the parities of a loop)
                   turn_X, turn_X*|turn_X|          distance travelled since the last turning point
                   play_XV_m                        (V - play_w(V)) / w, a bridge's own output
                                                    through a backlash of width w (a grid)
                   loop_XV_m                        the widest play less its first-loading
                                                    curve clip(V / w): a Masing (Iwan) joint's
                                                    loop, whose first loading is the mean response
    bidirectional  |FXV|, FXV*|FXV|, FXV^2*|FXV|,   sign-dependent terms keyed to the output
                   absload_X, absload2_X,           (AIAA R-091): with the base cubic, a cubic of
                   absload3_X                       its own on each side of zero; and the same
                                                    keyed to the load x = L_X / capacity: |x|,
                                                    x|x|, x²|x|; a slope (|V|, |x|) or a one-sided
                                                    curvature (V|V| with V²|V|, x|x| with x²|x|)
    cross_terms    FXV^2*FZV, FXV*FYV*FZV, ...       monomials up to degree 3 the base model lacks
    creep          creep_XV_m                       Σ ΔV exp(-age/τ_m) over the bridge's load
                                                    steps, τ_m on a grid: the time constant is
                                                    estimated
    excitation     exc_m_X                          a common gain g(t) x the total load on X; g a
                                                    line in time or steps (one fit for all six)
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

EFFECT_NAMES = (
    'temperature',
    'zero_drift',
    'hysteresis',
    'bidirectional',
    'cross_terms',
    'tare',
    'creep',
    'excitation',
)
# Families whose terms are fitted at calibration but not applied live (they follow the campaign's
# time line or load history, which the live calibrator does not have).
NUISANCE_EFFECTS = ('zero_drift', 'creep', 'excitation')
# Families of generic shape, adopted only where no specific family explains the structure.
GENERIC_FAMILIES = ('cross_terms', 'zero_drift')
# Families whose coefficients a physical effect keeps over the campaign (the time-keyed ones,
# temperature, zero drift, excitation, follow time themselves and are not tested so).
STATIC_FAMILIES = ('hysteresis', 'bidirectional', 'cross_terms', 'creep')


@dataclass(frozen=True)
class CandidateFamily:
    """The terms one physical effect may add to a component."""

    name: str
    groups: tuple[tuple[str, ...], ...]  # canonical term names, in groups added as a whole
    max_groups: int  # forward selection adds at most this many per component
    labels: Mapping[tuple[str, ...], str]  # what a group means, for the evidence line
    frequencies_hz: tuple[float, ...] = ()  # zero_drift: each group's frequency (Hz)

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


def temperature_family(outputs: Sequence[str], variable: str = 'dT') -> CandidateFamily:
    """Zero and sensitivity moving with the temperature difference `variable` (a table's
    temperature channel TEMP enters as dTEMP), linearly and by its square.
    """
    d = variable
    return _single(
        'temperature',
        [d, f'{d}^2'] + [f'{d}*{v}' for v in outputs] + [f'{d}^2*{v}' for v in outputs],
        3,
    )


def channel_family(
    outputs: Sequence[str], variable: str, varies_within_series: bool = True
) -> CandidateFamily:
    """Any other extra channel (a position, a supply voltage: interfaces.md `channel`): a zero
    and a sensitivity linear in its difference from the mean, dJAW and dJAW*rN1. A channel
    constant within each load series offers only the products: its term alone is what the series
    tares already carry, never an effect.
    """
    alone = [variable] if varies_within_series else []
    return _single('channel', alone + [f'{variable}*{v}' for v in outputs], 3)


def hysteresis_family(components: Sequence[str], outputs: Sequence[str]) -> CandidateFamily:
    """Loops keyed to a component's own load history (dir_X: constant, slope and even loops;
    turn_X: growing away from the turning point, linearly or by Rayleigh's square) and to each
    bridge's own output history (play_XV_m: the play operator of a Prandtl-Ishlinskii model, width
    PLAY_WIDTHS[m] of rated output; a gauge's loop follows its strain, which on a coupled balance
    moves with other components' loads too, and a small reversal makes a small loop; loop_XV_m:
    the widest play without its first-loading curve, see play_loop). diagnose.py offers a
    component its own load-keyed terms and every bridge's output-keyed ones.
    """
    return _single(
        'hysteresis',
        [f'dir_{c}' for c in components]
        + [f'dir_{c}*{v}' for c, v in zip(components, outputs)]
        + [f'dir_{c}*|{v}|' for c, v in zip(components, outputs)]
        + [f'turn_{c}' for c in components]
        + [f'turn_{c}*|turn_{c}|' for c in components]
        + [f'play_{v}_{m}' for v in outputs for m in range(1, len(PLAY_WIDTHS) + 1)]
        + [f'loop_{v}_{len(PLAY_WIDTHS)}' for v in outputs],
        3,
    )


def bidirectional_family(
    outputs: Sequence[str], components: Sequence[str] = ()
) -> CandidateFamily:
    """Sign-dependent terms keyed to the bridge output (AIAA R-091) and to the load (absload_X),
    in two kinds of group: a slope that differs with the sign (|V|; |x|) and a curvature on one
    side of zero (V|V| with V²|V|; x|x| with x²|x|).

    sign(V) x (V, V², V³) = |V|, V|V|, V²|V|: beside the base cubic they let the response be a
    different cubic for each sign of the output (a continuous one: no sign(V) step). With the
    base's V² and V³, the pair V|V|, V²|V| is a quadratic and a cubic on one side only, with the
    slope at zero unchanged: what a flexure buckling in compression does (|x|^2.5 on x < 0), a
    shape between the two. Offered one by one, the first was taken and the second's step missed
    the family's level; the one term fitted with coefficients that moved with the gravity
    direction (B660H M_Y, curvature on every bridge: x²|x| alone Chow p 5e-6, with x|x| 0.1) and
    the effect was left `unexplained` there (6/10 campaigns right; 8/10 as pairs).
    The load-keyed terms (x = L_X / capacity) do the same on the side of the component's load:
    on a coupled bridge the output's sign is not the load's (B660H M_Z: a curvature on negative
    M_Z loads on every bridge left 1.89 floors with the output terms and |x|, 0.41 with x|x| and
    x²|x| too; noise-free). Once a group is found on a component, families._settle_sign_shape
    drops a pair's term the points do not resolve and completes a shape that one pair fits only
    with moving coefficients by the other key's pair (LMC6522, curvature on every bridge: 10/10
    right, σ ≤ 1.12x and cross-validated ≤ 1.14x the clean floor; 9/10 and 1.21x before).
    """
    linear, quadratic, cubic = ABSOLUTE_LOAD_TERMS
    slope: list[tuple[str, ...]] = [(f'|{v}|',) for v in outputs]
    slope += [(f'{linear}_{c}',) for c in components]
    curvature: list[tuple[str, ...]] = []
    curvature += [(canonical(f'{v}*|{v}|'), canonical(f'{v}^2*|{v}|')) for v in outputs]
    curvature += [(f'{quadratic}_{c}', f'{cubic}_{c}') for c in components]
    return CandidateFamily('bidirectional', tuple(slope + curvature), 3, {})


def own_terms_only(
    family: CandidateFamily, component: str, output: str, components: Sequence[str]
) -> tuple:
    """The groups a component is offered: bidirectional only its own bridge's and load's (a
    sensitivity that differs with the sign of that component's load); hysteresis its own load
    history's and every bridge's output history's; other families all.
    """
    if family.name == 'bidirectional':
        own = {
            f'|{output}|',
            canonical(f'{output}*|{output}|'),
            canonical(f'{output}^2*|{output}|'),
        } | {f'{name}_{component}' for name in ABSOLUTE_LOAD_TERMS}
        return tuple(g for g in family.groups if set(g) <= own)
    if family.name == 'hysteresis':
        others = {c for c in components if c != component}
        return tuple(
            g
            for g in family.groups
            if not any(t.startswith((f'dir_{c}', f'turn_{c}')) for t in g for c in others)
        )
    return family.groups


def creep_family(
    outputs: Sequence[str], time_constants_s: Sequence[float] | np.ndarray, max_groups: int = 2
) -> CandidateFamily:
    groups: list[tuple[str, ...]] = []
    labels: dict[tuple[str, ...], str] = {}
    for v in outputs:
        for m, tau in enumerate(time_constants_s, start=1):
            group = (f'creep_{v}_{m}',)
            groups.append(group)
            labels[group] = f'creep of {v} (τ ≈ {tau:.0f} s)'
    return CandidateFamily('creep', tuple(groups), max_groups, labels)


def excitation_family(
    components: Sequence[str], basis_labels: Sequence[str], max_groups: int = 4
) -> CandidateFamily:
    """Groups are basis functions of g(t); a group's terms are that function x each component's
    load (one column per component; the joint test in diagnose.py shares the coefficient).
    """
    groups = tuple(
        tuple(f'exc_{m}_{c}' for c in components) for m in range(1, len(basis_labels) + 1)
    )
    labels = {g: basis_labels[m] for m, g in enumerate(groups)}
    return CandidateFamily('excitation', groups, max_groups, labels)


def cross_terms_family(
    outputs: Sequence[str], base_terms: Sequence[str], max_groups: int = 4
) -> CandidateFamily:
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
    groups: list[tuple[str, ...]] = []
    labels: dict[tuple[str, ...], str] = {}
    for m, f in enumerate(frequencies_hz, start=1):
        group = (f'drift_sin_{m}', f'drift_cos_{m}')
        groups.append(group)
        labels[group] = f'{1.0 / f:.0f} s'
    return CandidateFamily(
        'zero_drift', tuple(groups), max_groups, labels, tuple(float(f) for f in frequencies_hz)
    )


# --- the variables ----------------------------------------------------------------------------
def refer_to_zero_points(values, times_s, is_zero_point, orientation) -> np.ndarray:
    """Values (N,) or (N, m) minus their interpolation between the bracketing zero points,
    §5(4).
    """
    values = np.asarray(values, dtype=float)
    column = values.ndim == 1
    referred = subtract_zero_points(
        times_s, values[:, None] if column else values, is_zero_point, orientation
    ).zeroed_outputs_mv
    return referred[:, 0] if column else referred


# A load change below this fraction of capacity is no reversal (see load_directions). The live
# LoadHistory (live/calibrator_core.py) uses 0.005 from its last reversal point; 0.005 here left
# the simulated M_Y loops partly unexplained (their small steps do reverse the simulated gauge).
DIRECTION_THRESHOLD = 1e-3


def load_directions(loads, times_s, capacity) -> np.ndarray:
    """(N, n) +1 where the load on a component last rose, -1 where it last fell, in time order.

    Starts rising, as the simulated balance and the live LoadHistory do; a change smaller than
    DIRECTION_THRESHOLD of capacity keeps the previous direction: the same load hung again, or the
    estimated body's tare moving by a hair when the body is turned over (1.6e-4 N·m of M_X on
    LMC6522, 1e-6 of capacity, flipped dir_MX at every orientation change and made its loop terms
    fit differently in the two halves of the campaign).
    """
    loads = np.atleast_2d(np.asarray(loads, dtype=float))
    order = np.argsort(np.asarray(times_s, dtype=float), kind='stable')
    steps = np.diff(loads[order], axis=0)
    sign = np.where(
        np.abs(steps) > DIRECTION_THRESHOLD * np.asarray(capacity, float), np.sign(steps), 0.0
    )
    sign = np.vstack([np.ones((1, loads.shape[1])), sign])
    rows = np.arange(len(sign))[:, None] * np.ones((1, loads.shape[1]), dtype=int)
    last = np.maximum.accumulate(np.where(sign != 0, rows, 0), axis=0)  # forward fill
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
    kept = [i for i, g in enumerate(family.groups) if not set(g) & base]
    frequencies = tuple(family.frequencies_hz[i] for i in kept) if family.frequencies_hz else ()
    return CandidateFamily(
        family.name,
        tuple(family.groups[i] for i in kept),
        family.max_groups,
        family.labels,
        frequencies,
    )


def turning_distances(loads, times_s, direction, capacity) -> np.ndarray:
    """(N, n) signed distance (fraction of capacity) the load travelled since its last turning
    point: dir x |L - L at the last reversal|, in time order. A loop whose offset grows away from
    the turning point (Preisach / Madelung) follows it; turn·|turn| is Rayleigh's law.
    """
    loads = np.atleast_2d(np.asarray(loads, dtype=float))
    order = np.argsort(np.asarray(times_s, dtype=float), kind='stable')
    load, d = loads[order], np.asarray(direction, float)[order]
    turn = np.empty_like(load)
    at_turn = load[0].copy()
    for i in range(len(load)):
        if i > 0:
            at_turn = np.where(d[i] != d[i - 1], load[i - 1], at_turn)
        turn[i] = load[i] - at_turn
    out = np.empty_like(turn)
    out[order] = turn
    return out / np.asarray(capacity, float)


# Half-widths (fraction of rated output) of the play operators tried for output-keyed loops.
PLAY_WIDTHS = (0.02, 0.1, 0.3)


def play_lag(outputs, times_s, half_width) -> np.ndarray:
    """(N, n) (V - play(V)) / w in time order: ±1 once the output moved 2w past its last turning
    point, linear in between (one hysteron of a Prandtl-Ishlinskii model).
    """
    outputs = np.atleast_2d(np.asarray(outputs, dtype=float))
    order = np.argsort(np.asarray(times_s, dtype=float), kind='stable')
    v = outputs[order]
    half = np.asarray(half_width, float)
    lag = np.empty_like(v)
    state = v[0].copy()
    for i, value in enumerate(v):
        state = np.minimum(np.maximum(state, value - half), value + half)
        lag[i] = (value - state) / half
    out = np.empty_like(lag)
    out[order] = lag
    return out


def play_loop(outputs, times_s, half_width) -> np.ndarray:
    """(N, n) play_lag less its first-loading curve clip(V / w, -1, 1): zero while the output
    rises from the zero or falls to it for the first time, ±2 across the backlash after a reversal.

    A play's lag follows clip(V / w) on first loading, a static curve the base cubic does not hold
    at the widest w (0.3 of rated output). A joint whose first loading lies on the mean response
    (a Masing or Iwan joint: its backbone is part of the calibration) has a loop without it; with
    the play alone, the static remainder was left to the sign family's V|V| (B660H, a Masing loop
    on every bridge: `bidirectional` named beside the loop in 4 campaigns of 10, 1 with this term).
    """
    outputs = np.atleast_2d(np.asarray(outputs, dtype=float))
    half = np.asarray(half_width, float)
    return play_lag(outputs, times_s, half) - np.clip(outputs / half, -1.0, 1.0)


@dataclass(frozen=True)
class BridgeOutputs:
    """The bridge outputs the play operators follow, with their names and rated outputs."""

    values: np.ndarray  # (N, n) mV
    names: Sequence[str]  # (n,) e.g. FXV
    rated_mv: np.ndarray  # (n,) mV: the play widths are fractions of it


def direction_variables(
    loads,
    times_s,
    capacity,
    components,
    is_zero_point,
    orientation,
    outputs: BridgeOutputs | None = None,
    fitted_loads=None,
):
    """dir_X, turn_X (and with outputs: play_XV_m) referred to the zero points, and the raw ±1 load
    directions (N, n). turn_X is measured on fitted_loads (the base model's, from the outputs) when
    given: a column built from the applied loads, the fit's target, would fit part of the target.
    """
    raw = load_directions(loads, times_s, capacity)
    columns = [
        raw,
        turning_distances(loads if fitted_loads is None else fitted_loads, times_s, raw, capacity),
    ]
    names = [f'dir_{c}' for c in components] + [f'turn_{c}' for c in components]
    if outputs is not None:
        for m, width in enumerate(PLAY_WIDTHS, start=1):
            half = width * np.asarray(outputs.rated_mv, float)
            columns.append(play_lag(outputs.values, times_s, half))
            names += [f'play_{v}_{m}' for v in outputs.names]
        columns.append(play_loop(outputs.values, times_s, half))  # the widest play's loop alone
        names += [f'loop_{v}_{len(PLAY_WIDTHS)}' for v in outputs.names]
    referred = refer_to_zero_points(np.hstack(columns), times_s, is_zero_point, orientation)
    return {name: referred[:, i] for i, name in enumerate(names)}, raw


# The load-keyed sign variables, x = L_X / capacity_X: |x|, x|x|, x²|x|.
ABSOLUTE_LOAD_TERMS = ('absload', 'absload2', 'absload3')


def absolute_load_variables(loads, capacity, components) -> dict[str, np.ndarray]:
    """absload_X = |x|, absload2_X = x|x|, absload3_X = x²|x| with x = L_X / capacity_X: keyed
    to the sign of the load, not of the bridge output. Pass the *fitted* loads (from the outputs):
    |applied load| equals the target wherever it is positive.
    """
    loads = np.asarray(loads, dtype=float)
    variables = {}
    for k, c in enumerate(components):
        x = loads[:, k] / capacity[k]
        for power, name in enumerate(ABSOLUTE_LOAD_TERMS):
            variables[f'{name}_{c}'] = x**power * np.abs(x)
    return variables


def creep_time_constants(times_s) -> np.ndarray:
    """The grid of time constants (s) creep is tried with: 1/4 to 2 point spacings.

    Longer ones are not tried: a relaxation lasting many points looks, in point means, like the
    load history (hysteresis) or a drift, and the schedule cannot tell them apart.
    """
    times = np.sort(np.asarray(times_s, dtype=float))
    spacing = float(np.median(np.diff(times))) if len(times) > 1 else 1.0
    return spacing * np.array([0.25, 0.5, 1.0, 2.0])


def creep_variables(
    outputs_mv, times_s, time_constants_s, outputs_names, is_zero_point, orientation
):
    """creep_XV_m: the unrelaxed part Σ_i ΔV_i exp(-(t - t_i)/τ_m) of each bridge's load steps,
    t_i halfway between the two points, referred to the zero points.
    """
    outputs = np.asarray(outputs_mv, dtype=float)
    times = np.asarray(times_s, dtype=float)
    order = np.argsort(times, kind='stable')
    v, t = outputs[order], times[order]
    steps = np.vstack([np.zeros((1, v.shape[1])), np.diff(v, axis=0)])  # (N, 6)
    step_times = np.concatenate([[t[0]], 0.5 * (t[1:] + t[:-1])])
    age = t[:, None] - step_times[None, :]  # (N, N)
    columns, names = [], []
    for m, tau in enumerate(time_constants_s, start=1):
        kernel = np.where(age >= 0, np.exp(-np.clip(age, 0.0, None) / tau), 0.0)
        values = kernel @ steps
        for j, name in enumerate(outputs_names):
            column = np.empty(len(t))
            column[order] = values[:, j]
            columns.append(column)
            names.append(f'creep_{name}_{m}')
    referred = refer_to_zero_points(np.column_stack(columns), times, is_zero_point, orientation)
    return {name: referred[:, i] for i, name in enumerate(names)}


def excitation_basis(times_s, n_steps: int = 16) -> tuple[np.ndarray, list[str]]:
    """Candidate shapes of a common gain g(t): a line in time and steps at n_steps even times."""
    times = np.asarray(times_s, dtype=float)
    t0, span = float(times.min()), float(np.ptp(times)) or 1.0
    columns = [(times - t0) / span - 0.5]
    labels = ['a gain drifting linearly in time']
    for j in range(1, n_steps + 1):  # from 10 % to 90 % of the campaign: a step at its very
        # edge is a few points' offset
        when = t0 + span * (0.1 + 0.8 * (j - 1) / max(n_steps - 1, 1))
        columns.append((times >= when).astype(float) - 0.5)
        labels.append(f'a gain step at t ≈ {when - t0:.0f} s')
    return np.column_stack(columns), labels


def excitation_variables(basis, total_loads, components, is_zero_point, times_s, orientation):
    """exc_m_X = g_m(t) x total load on X (body weight included), referred to the zero points
    as the outputs it scales are.
    """
    total = np.asarray(total_loads, dtype=float)
    columns, names = [], []
    for m in range(basis.shape[1]):
        for k, c in enumerate(components):
            columns.append(basis[:, m] * total[:, k])
            names.append(f'exc_{m + 1}_{c}')
    referred = refer_to_zero_points(np.column_stack(columns), times_s, is_zero_point, orientation)
    return {name: referred[:, i] for i, name in enumerate(names)}
