"""A one-axis calibration's residual examined: the straight line of eqs. (25)-(26), then what it
lacks.

Points are taken in order (loading, unloading, perhaps repeated). The residual of the line y = a x
+ b is examined against three families, each a small set of columns added to the line:

    hysteresis     dir, dir*x, dir*x^2,      dir = +1 loading / -1 unloading (given or from the
                                              order of y); turn = reading's travel since the last
                                              turning point, signed: a loop growing away from it
                   turn, turn*|turn|          (linearly, or by Rayleigh's square); dir*x^2 with dir
                                              is the loop widest at mid-range
    nonlinearity   x^2, x^3                   x centred and scaled to ±1
    zero_drift     t, t^2                     t = point order, scaled to ±1

Per round, every family not yet adopted is tried by forward selection (partial F-test, level
alpha / terms in that family); it counts only if the leave-one-out (PRESS) σ improves too, and the
one with the largest BIC gain is adopted. Few points carry few terms: at most n // 4 columns in
all. When a runner-up about as good as the winner (score >= 0.8 of it) no longer passes once the
winner is in, the two explain the same residual and the order of the points cannot separate them: a
warning, and only the winner is adopted.

What remains is tested against the repeatability, when there is one: the given σ_x, σ_y (χ² of the
residual, σ_i² = σ_y² + a² σ_x²), otherwise the scatter of repeated points (same y, same direction:
pure error, a lack-of-fit F-test). Structure beyond it goes to an `unexplained` entry saying what
it follows most strongly; nothing is adopted for it. Without either yardstick it is not tested.

σ in % FS, FS = the largest |y| (interfaces.md, "One-axis calibration with its residual examined").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.stats

from ..diagnosis.statistics import fit_columns
from ..fit.least_squares import LeastSquares

FAMILIES = ('hysteresis', 'nonlinearity', 'zero_drift')


@dataclass(frozen=True)
class OneAxisSettings:
    alpha: float = 0.01  # per family, Bonferroni over its terms
    alpha_lack_of_fit: float = 0.001
    max_rounds: int = 3
    terms_per_point: float = 0.25  # at most n x this columns in all (the line included)
    equal_score: float = 0.8


@dataclass(frozen=True)
class OneAxisEffect:
    name: str  # hysteresis | nonlinearity | zero_drift | unexplained
    evidence: str
    terms: tuple[str, ...]
    sigma_after_pct_fs: float

    def to_report(self) -> dict:
        return {
            'name': self.name,
            'components': ['y'],
            'evidence': self.evidence,
            'terms': list(self.terms),
            'sigma_after_pct_fs': {'y': round(float(self.sigma_after_pct_fs), 4)},
        }


@dataclass(frozen=True)
class OneAxisExamination:
    terms: tuple[str, ...]  # adopted columns: '1', 'x', then the effects'
    coefficients: np.ndarray  # per term, in the units of y (columns scaled as described)
    effects: tuple[OneAxisEffect, ...]  # most important first; an 'unexplained' one last
    sigma_pct_fs: dict  # {'before': σ of the line, 'after': adopted}
    sigma_pct_fs_crossval: dict
    repeatability_pct_fs: float | None
    residuals_before: np.ndarray
    residuals_after: np.ndarray
    direction: np.ndarray
    warnings: tuple[str, ...] = field(default_factory=tuple)

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)

    def to_report(self) -> dict:
        return {
            'sigma_pct_fs': {k: round(float(v), 4) for k, v in self.sigma_pct_fs.items()},
            'sigma_pct_fs_crossval': {
                k: round(float(v), 4) for k, v in self.sigma_pct_fs_crossval.items()
            },
            'effects': [e.to_report() for e in self.effects],
            'repeatability_pct_fs': None
            if self.repeatability_pct_fs is None
            else round(float(self.repeatability_pct_fs), 4),
            'adopted_terms': list(self.terms),
            # per term; x^k, dir*x... use x centred and scaled to ±1, t the point order scaled to
            # ±1
            'adopted_coefficients': {t: float(c) for t, c in zip(self.terms, self.coefficients)},
            'warnings': list(self.warnings),
        }


def directions_from_order(y) -> np.ndarray:
    """+1 where y last rose, -1 where it last fell, in the order given (starts loading)."""
    y = np.asarray(y, dtype=float)
    direction = np.ones(len(y))
    for i in range(1, len(y)):
        step = y[i] - y[i - 1]
        direction[i] = np.sign(step) if step != 0 else direction[i - 1]
    return direction


def _scaled(values) -> np.ndarray:
    values = np.asarray(values, dtype=float)
    half = np.ptp(values) / 2.0
    return (values - (values.max() + values.min()) / 2.0) / (half if half > 0 else 1.0)


def candidate_columns(x, y, direction) -> dict[str, dict[str, np.ndarray]]:
    xs = _scaled(x)
    t = _scaled(np.arange(len(x)))
    # from the readings, not from y: columns built from the target itself would fit it exactly
    turn = np.zeros(len(x))
    at_turn = x[0]
    for i in range(1, len(x)):
        if direction[i] != direction[i - 1]:
            at_turn = x[i - 1]
        turn[i] = x[i] - at_turn
    turn = turn / max(np.max(np.abs(x)), 1e-300)
    return {
        'hysteresis': {
            'dir': direction,
            'dir*x': direction * xs,
            'dir*x^2': direction * xs**2,
            'turn': turn,
            'turn*|turn|': turn * np.abs(turn),
        },
        'nonlinearity': {'x^2': xs**2, 'x^3': xs**3},
        'zero_drift': {'t': t, 't^2': t**2},
    }


def _sigma(residuals, full_scale) -> float:
    return float(np.sqrt(np.mean(residuals**2)) / full_scale * 100.0)


def _select(columns: dict, design: np.ndarray, y, max_columns: int, alpha: float):
    """Forward selection within one family; (names, fit) or ([], None)."""
    names: list[str] = []
    current = fit_columns(design, y)
    available = dict(columns)
    while available and design.shape[1] + len(names) < max_columns:
        trials = []
        for name, column in available.items():
            trial = fit_columns(
                np.column_stack([design] + [columns[n] for n in names] + [column]), y
            )
            if trial.rank <= current.rank or trial.dof <= 0:
                continue
            f = (current.rss - trial.rss) / max(trial.rss / trial.dof, 1e-300)
            trials.append((float(scipy.stats.f.sf(f, 1, trial.dof)), name, trial))
        if not trials:
            break
        p, name, trial = min(trials, key=lambda t: t[0])
        if p * len(columns) > alpha:
            break
        names.append(name)
        current = trial
        del available[name]
    return names, (current if names else None)


def examine_line(
    x, y, direction=None, sigma_x=None, sigma_y=None, settings: OneAxisSettings = OneAxisSettings()
) -> OneAxisExamination:
    """The line y = a x + b and the effects its residual shows (module docstring)."""
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    n = len(x)
    direction = (
        directions_from_order(y)
        if direction is None
        else np.asarray(direction, dtype=float).ravel()
    )
    if direction.shape != x.shape or not np.all(np.isin(direction, (-1.0, 1.0))):
        raise ValueError('direction must be +1 (loading) or -1 (unloading) for every point')
    full_scale = float(np.max(np.abs(y)))
    if full_scale <= 0:
        raise ValueError('all y are zero: no full scale')
    families = candidate_columns(x, y, direction)
    design = np.column_stack([np.ones(n), x])
    terms = ['1', 'x']
    base = fit_columns(design, y)
    current = base
    max_columns = max(2, int(n * settings.terms_per_point))
    effects: list[tuple[str, list[str], LeastSquares, LeastSquares]] = []
    warnings: list[str] = []
    close: list = []
    adopted: set[str] = set()
    for _ in range(settings.max_rounds):
        candidates = []
        for family in FAMILIES:
            if family in adopted:
                continue
            names, fit = _select(families[family], design, y, max_columns, settings.alpha)
            if fit is None or np.sum(fit.press_residuals**2) >= np.sum(current.press_residuals**2):
                continue
            gain = n * np.log(current.rss / max(fit.rss, 1e-300)) - len(names) * np.log(n)
            if gain > 0:
                candidates.append((gain, family, names, fit))
        present = {c[1] for c in candidates}
        for won, runner in close:
            if runner not in present:
                warnings.append(
                    f'{won} and {runner} explain the same residual about equally: the order of '
                    f'the points cannot separate them; only {won} was adopted'
                )
        if not candidates:
            break
        candidates.sort(key=lambda c: -c[0])
        gain, family, names, fit = candidates[0]
        close = [(family, c[1]) for c in candidates[1:] if c[0] >= settings.equal_score * gain]
        effects.append((family, names, current, fit))
        design = np.column_stack([design] + [families[family][name] for name in names])
        terms += names
        current = fit
        adopted.add(family)

    found = [
        OneAxisEffect(
            family,
            _evidence(family, names, before, after, full_scale),
            tuple(names),
            _sigma(after.residuals, full_scale),
        )
        for family, names, before, after in effects
    ]
    repeatability, unexplained = _lack_of_fit(
        _Points(x, y, direction, full_scale), current, terms, sigma_x, sigma_y, settings
    )
    if unexplained is not None:
        found.append(unexplained)
    found_sorted = sorted(
        [e for e in found if e.name != 'unexplained'],
        key=lambda e: -_removed(e, effects, full_scale),
    ) + [e for e in found if e.name == 'unexplained']
    return OneAxisExamination(
        tuple(terms),
        current.coefficients,
        tuple(found_sorted),
        {
            'before': _sigma(base.residuals, full_scale),
            'after': _sigma(current.residuals, full_scale),
        },
        {
            'before': _sigma(base.press_residuals, full_scale),
            'after': _sigma(current.press_residuals, full_scale),
        },
        repeatability,
        base.residuals,
        current.residuals,
        direction,
        tuple(warnings),
    )


def _removed(effect, effects, full_scale) -> float:
    for family, _, before, after in effects:
        if family == effect.name:
            return max(before.rss - after.rss, 0.0)
    return 0.0


def _evidence(family, names, before, after, full_scale) -> str:
    q = after.rank - before.rank
    f = (before.rss - after.rss) / q / max(after.rss / after.dof, 1e-300)
    p = float(scipy.stats.f.sf(f, q, after.dof))
    removed_pct_fs = (
        np.sqrt(max(before.rss - after.rss, 0.0) / len(after.residuals)) / full_scale * 100
    )
    return (
        f'residual follows {" + ".join(names)}: F = {f:.3g} (p = {p:.1g}), removes '
        f'{removed_pct_fs:.3f} % FS (σ {_sigma(before.residuals, full_scale):.3f} → '
        f'{_sigma(after.residuals, full_scale):.3f}, PRESS σ '
        f'{_sigma(before.press_residuals, full_scale):.3f} → '
        f'{_sigma(after.press_residuals, full_scale):.3f})'
    )


@dataclass(frozen=True)
class _Points:
    """The points examined, in the order taken: readings x, values y, direction (+1 loading, -1
    unloading) and the full scale FS = the largest |y|.
    """

    x: np.ndarray
    y: np.ndarray
    direction: np.ndarray
    full_scale: float


def _lack_of_fit(
    points: _Points,
    fit: LeastSquares,
    terms: list[str],
    sigma_x,
    sigma_y,
    settings: OneAxisSettings,
) -> tuple[float | None, OneAxisEffect | None]:
    """(repeatability % FS or None, an 'unexplained' effect or None)."""
    x, y, direction, full_scale = points.x, points.y, points.direction, points.full_scale
    residuals = fit.residuals
    if sigma_x is not None or sigma_y is not None:
        slope = fit.coefficients[terms.index('x')]
        sx = np.broadcast_to(np.asarray(0.0 if sigma_x is None else sigma_x, float), x.shape)
        sy = np.broadcast_to(np.asarray(0.0 if sigma_y is None else sigma_y, float), y.shape)
        variance = sy**2 + (slope * sx) ** 2
        if np.all(variance > 0):
            chi2 = float(np.sum(residuals**2 / variance))
            p = float(scipy.stats.chi2.sf(chi2, fit.dof))
            repeatability = float(np.sqrt(np.mean(variance)) / full_scale * 100.0)
            ratio = np.sqrt(chi2 / fit.dof)
            how = 'the given σ_x, σ_y'
            return repeatability, _unexplained(p, ratio, how, residuals, points, settings)
    keys = np.round(y / full_scale, 9) * direction
    groups = [np.flatnonzero(keys == k) for k in np.unique(keys)]
    groups = [g for g in groups if len(g) >= 2]
    nu = sum(len(g) - 1 for g in groups)
    if nu < 2:
        return None, None
    pure = sum(float(np.sum((residuals[g] - residuals[g].mean()) ** 2)) for g in groups)
    repeatability = float(np.sqrt(pure / nu) / full_scale * 100.0)
    lof_dof = fit.dof - nu
    if lof_dof <= 0 or pure <= 0:
        return repeatability, None
    f = (fit.rss - pure) / lof_dof / (pure / nu)
    p = float(scipy.stats.f.sf(f, lof_dof, nu))
    how = f'{nu} repeated points (same load, same direction)'
    return repeatability, _unexplained(p, np.sqrt(max(f, 0.0)), how, residuals, points, settings)


def _unexplained(
    p: float,
    ratio: float,
    how: str,
    residuals: np.ndarray,
    points: _Points,
    settings: OneAxisSettings,
) -> OneAxisEffect | None:
    """The 'unexplained' effect when the residual is beyond the repeatability (lack of fit p below
    settings.alpha_lack_of_fit), saying what it follows most strongly; else None.
    """
    if not p < settings.alpha_lack_of_fit:
        return None
    y, full_scale = points.y, points.full_scale
    trackers = {
        'point order': np.arange(len(y), dtype=float),
        'load': y,
        'load history': points.direction,
        'load squared': (y / full_scale) ** 2,
    }
    best, r_best = 'nothing found', 0.0
    for name, values in trackers.items():
        if np.ptp(values) > 0:
            r = abs(float(np.corrcoef(values, residuals)[0, 1]))
            if r > r_best:
                best, r_best = name, r
    tracks = best if r_best * np.sqrt(len(y)) > 3.0 else 'nothing found'
    evidence = f'residual {ratio:.1f}x what {how} allow (lack of fit p = {p:.1g})' + (
        f'; follows {tracks} (r = {r_best:.2f})'
        if tracks != 'nothing found'
        else '; follows nothing examined'
    )
    return OneAxisEffect('unexplained', evidence, (), _sigma(residuals, full_scale))
