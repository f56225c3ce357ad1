"""The diagnosis on what a table carries (interfaces.md, "Effects found in table calibrations").

The same machinery as the bag diagnosis (diagnose.py): candidate families of terms (candidates.py:
hysteresis keyed to the load direction, zero_drift to the point order, the bidirectional sign
terms, temperature, and `channel` for any other extra channel), forward selection by partial
F-tests Bonferroni-corrected within a family (statistics.forward_select), families ranked by their
BIC gain, the best added and the search repeated. A table has no zero points, no times and no
gravity directions: the fit is the direct form (TM-663: loads from the outputs) with the series
tares as columns, and the tests are ordinary (not whitened).

An effect is adopted only where it lowers the cross-validated σ beyond chance, judged at the level
at which its regressor varies:
- a regressor that varies from point to point: leave-one-out (PRESS) residuals with and without
  it, a one-sided Wilcoxon signed-rank test of the drop of their squares (level ALPHA_CROSSVAL);
- a channel constant within each load series: whole series left out (the left-out series' tare
  estimated from its own points with the model held fixed), and the gain in fit tested against
  the channel's values permuted among the series. A term in such a channel alone is what the
  series tares carry, never an effect (channel_family, temperature without its lone terms).

A channel that follows the applied loads (a deflection, a position read off the rig) is not
examined: its terms would fit the target itself. Point order is a regressor only in the series
that return to a load they had earlier (calibration_points.returning_series).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np
import scipy.stats

from ..accuracy.sigma import sigma_pct_fs
from ..calibration_points import CalibrationPoints, ExtraChannel
from ..fit.least_squares import LeastSquares
from ..fit.series_tares import series_indicator
from ..fit.svd import minimum_norm_solve
from ..model.terms import as_variables, design_matrix, parse_terms, Term
from .candidates import (
    absolute_load_variables,
    bidirectional_family,
    CandidateFamily,
    canonical,
    channel_family,
    hysteresis_family,
    own_terms_only,
    temperature_family,
    without_base_terms,
)
from .statistics import fit_columns, forward_select

TABLE_EFFECTS = ('temperature', 'channel', 'zero_drift', 'hysteresis', 'bidirectional')
ALPHA = 1e-4  # one family's forward selection (Bonferroni within it), as diagnose.py
ALPHA_CROSSVAL = 1e-3  # the cross-validated σ lower beyond chance, per component
PERMUTATIONS = 1999  # among series (p down to 5e-4), for a channel constant within each series
TRACKS_LOAD_R2 = 0.5  # a channel this much explained by the applied loads follows the loads
MAX_ROUNDS = 5


@dataclass(frozen=True)
class TableEffect:
    """One effect found in a table's residuals and added to the model."""

    name: str  # one of TABLE_EFFECTS
    components: tuple[str, ...]
    evidence: str
    terms: tuple[str, ...]
    channel: str | None  # the extra channel's symbol (temperature, channel)
    sigma_before_pct_fs: Mapping[str, float]  # eq. (44) RMS, just before it was added
    sigma_after_pct_fs: Mapping[str, float]
    crossval_before_pct_fs: Mapping[str, float]
    crossval_after_pct_fs: Mapping[str, float]
    crossval_p: Mapping[str, float]

    def to_report(self) -> dict:
        """The entry of report.json's "effects" (refit's schema, plus the channel)."""
        entry: dict = {
            'name': self.name,
            'components': list(self.components),
            'evidence': self.evidence,
            'terms': list(self.terms),
            'sigma_after_pct_fs': {
                c: round(float(v), 5) for c, v in self.sigma_after_pct_fs.items()
            },
        }
        if self.channel is not None:
            entry['channel'] = self.channel
        entry['sigma_before_pct_fs'] = {
            c: round(float(v), 5) for c, v in self.sigma_before_pct_fs.items()
        }
        entry['sigma_crossval_pct_fs'] = {
            'before': {c: round(float(v), 5) for c, v in self.crossval_before_pct_fs.items()},
            'after': {c: round(float(v), 5) for c, v in self.crossval_after_pct_fs.items()},
        }
        entry['adopted'] = True
        return entry


@dataclass(frozen=True)
class TableDiagnosis:
    effects: tuple[TableEffect, ...]  # most important first
    added_terms: tuple[str, ...]  # union over the components, in the order adopted
    variables: Mapping[str, np.ndarray]  # extra model variables per point (dTEMP, dir_N1 ...)
    channels: tuple[ExtraChannel, ...]  # the extra channels the added terms use
    examined: tuple[str, ...]
    skipped: Mapping[str, str]
    warnings: tuple[str, ...] = ()


class _Columns:
    """Design columns by term name over the outputs and the extra variables (cached)."""

    def __init__(self, points: CalibrationPoints, variables: Mapping[str, np.ndarray]):
        self.names = tuple(points.output_symbols) + tuple(variables)
        self.values = np.column_stack(
            [points.outputs] + [np.asarray(v, float)[:, None] for v in variables.values()]
        )
        self.n = points.points
        self.cache: dict[str, np.ndarray] = {}

    def __call__(self, names: Sequence[str]) -> np.ndarray:
        missing = [t for t in dict.fromkeys(names) if t not in self.cache]
        if missing:
            matrix = design_matrix(
                parse_terms(missing), as_variables(self.names, self.values), self.n
            )
            for j, name in enumerate(missing):
                self.cache[name] = matrix[:, j]
        if not names:
            return np.zeros((self.n, 0))
        return np.column_stack([self.cache[t] for t in names])


def _where_reversing(direction: np.ndarray, series: np.ndarray) -> np.ndarray:
    """(N, m) the directions, set to 0 in every series (and column) where they do not take
    both signs.
    """
    out = np.array(direction, dtype=float)
    for s in np.unique(series):
        mask = series == s
        both = np.any(out[mask] > 0, axis=0) & np.any(out[mask] < 0, axis=0)
        out[np.ix_(mask, ~both)] = 0.0
    return out


def _even_part(family: CandidateFamily) -> CandidateFamily:
    """The sign family's terms even in their variable (|V|, V²|V|, |x|, x²|x|): a response that
    differs between the signs of the load. The odd ones (V|V|, x|x|) are a nonlinearity of the
    same shape on both sides (a knee at low load, tanh-like), which is not a sign effect and
    which, without the bag's loading/unloading contrasts (loop_or_sign.py), nothing here could
    tell from one.
    """
    groups = []
    for group in family.groups:
        even = tuple(t for t in group if not _odd(t))
        if even:
            groups.append(even)
    return CandidateFamily(family.name, tuple(groups), family.max_groups, family.labels)


def _odd(term: str) -> bool:
    """A term odd in its variable: the plain powers sum to an odd number (|V| is even); of the
    load-keyed ones x|x| (absload2).
    """
    if term.startswith('absload'):
        return term.startswith('absload2_')
    factors = parse_terms([term])[0].factors
    return sum(f.power for f in factors if not f.absolute) % 2 == 1


def _own_output(points: CalibrationPoints, k: int) -> str:
    """The bridge that follows load k most (its own, on a balance with one bridge a load)."""
    outputs = points.outputs
    if outputs.shape[1] == len(points.load_symbols):
        return points.output_symbols[k]
    load = points.applied_loads[:, k] - points.applied_loads[:, k].mean()
    centred = outputs - outputs.mean(axis=0)
    r = np.abs(centred.T @ load) / np.maximum(
        np.linalg.norm(centred, axis=0) * np.linalg.norm(load), 1e-300
    )
    return points.output_symbols[int(np.argmax(r))]


def _tracks_loads(channel: np.ndarray, points: CalibrationPoints, onehot: np.ndarray) -> float:
    """Fraction of the channel's variance within the series that the applied loads explain."""
    within = fit_columns(onehot, channel).residuals
    if float(within @ within) <= 1e-300:
        return 0.0
    relative = points.applied_loads / points.capacity
    loads = np.hstack([relative, relative**2, np.abs(relative), onehot])
    rest = fit_columns(loads, channel).residuals
    return float(1.0 - (rest @ rest) / (within @ within))


def _series_out_residuals(design: np.ndarray, target: np.ndarray, series: np.ndarray, p: int):
    """Whole series left out: fit the others, predict the series with its own tare (the mean of
    its residuals, the model held fixed). design's first p columns are the model's terms.
    """
    out = np.zeros(len(target))
    for s in np.unique(series):
        mask = series == s
        fit = fit_columns(design[~mask], target[~mask])
        predicted = design[mask, :p] @ fit.coefficients[:p]
        miss = target[mask] - predicted
        out[mask] = miss - miss.mean()
    return out


def _drop_p(before: np.ndarray, after: np.ndarray) -> float:
    """One-sided p of the squared cross-validated residuals being lower after than before."""
    difference = before**2 - after**2
    if not np.any(difference != 0):
        return 1.0
    return float(scipy.stats.wilcoxon(difference, alternative='greater').pvalue)


def diagnose_points(
    points: CalibrationPoints,
    base_terms: Sequence[str],
    *,
    effects: Sequence[str] = TABLE_EFFECTS,
    alpha: float = ALPHA,
    alpha_crossval: float = ALPHA_CROSSVAL,
    permutations: int = PERMUTATIONS,
    seed: int = 0,
) -> TableDiagnosis:
    """Examine the residuals of the direct fit of `base_terms` (series tares included) and add
    the effects that lower the cross-validated σ beyond chance.
    """
    components, outputs_names = points.load_symbols, points.output_symbols
    capacity = points.capacity
    _, _, onehot = series_indicator(points.series)
    skipped: dict[str, str] = {}
    warnings: list[str] = []
    variables: dict[str, np.ndarray] = {}
    families: list[tuple[CandidateFamily, str | None]] = []  # with the channel's variable
    series_level: set[str] = set()  # variables constant within each series
    channel_of: dict[str, ExtraChannel] = {}

    base = list(base_terms)
    base_columns = _Columns(points, {})
    base_design = np.hstack([base_columns(base), -onehot])
    base_fits = [
        fit_columns(base_design, points.applied_loads[:, k]) for k in range(len(components))
    ]
    fitted_loads = points.applied_loads - np.column_stack([f.residuals for f in base_fits])

    wanted = set(effects)
    if 'hysteresis' in wanted:
        direction = points.load_direction
        if np.any(_where_reversing(direction[:, None], points.series) != 0):
            # the point's direction (interfaces.md: the magnitude of the load that changed most
            # grew or shrank), and each load's own signed direction within its series (what the
            # live calibrator's load history keeps: dir_X, candidates.hysteresis_family): a loop
            # symmetric about zero load is keyed to the second, a loop in |load| to the first
            # only in series where the direction reverses: in a series that only rises the
            # direction is 0 at its first point and +1 after, a step in the load that a
            # nonlinearity near zero (a knee) fills as well as a loop would
            variables['dir'] = _where_reversing(direction[:, None], points.series)[:, 0]
            signed = _where_reversing(points.signed_directions, points.series)
            for k, c in enumerate(components):
                variables[f'dir_{c}'] = signed[:, k]
            family = hysteresis_family(components, outputs_names)
            keep = [g for g in family.groups if all(t.startswith('dir_') for t in g)]
            keep += [('dir',)] + [(f'dir*{v}',) for v in outputs_names]
            keep += [(canonical(f'dir*|{v}|'),) for v in outputs_names]
            families.append(
                (CandidateFamily('hysteresis', tuple(keep), family.max_groups, {}), None)
            )
        else:
            skipped['hysteresis'] = (
                'no series reverses its load: direction cannot be told from the load'
            )
    if 'zero_drift' in wanted:
        returning = points.returning_series
        if returning.any():
            order = points.order_in_series.copy()
            for s in np.unique(points.series):
                mask = points.series == s
                order[mask] = (order[mask] - order[mask].mean()) / max(int(mask.sum()), 1)
            variables['order'] = np.where(returning, order, 0.0)
            families.append(
                (CandidateFamily('zero_drift', (('order',), ('order^2',)), 2, {}), None)
            )
        else:
            skipped['zero_drift'] = (
                'no series returns to a load it had: order cannot be told from the load'
            )
    if 'bidirectional' in wanted:
        # a sign term even in its variable stands in for a missing square: offered only for
        # the bridges (and the loads whose own bridge) the base model has the square of
        squared = {v for v in outputs_names if Term.parse(f'{v}^2').name in set(base)}
        keyed = [c for k, c in enumerate(components) if _own_output(points, k) in squared]
        if squared:
            variables.update(absolute_load_variables(fitted_loads, capacity, components))
            family = _even_part(bidirectional_family(sorted(squared), keyed))
            families.append((family, None))
        else:
            skipped['bidirectional'] = (
                'the base model has no square of a bridge output: a sign term would stand in '
                'for it'
            )
    for channel in points.channels:
        if channel.kind not in wanted:
            continue
        values = channel.values - channel.reference
        if not np.all(np.isfinite(values)) or float(np.ptp(values)) <= 0:
            skipped[channel.symbol] = f'channel {channel.symbol} never changes'
            continue
        tracked = _tracks_loads(values, points, onehot)
        if tracked >= TRACKS_LOAD_R2:
            warnings.append(
                f'channel {channel.symbol} follows the applied loads ({tracked:.0%} of its '
                'variance within the series): not examined as an effect (its terms would fit '
                'the loads themselves)'
            )
            skipped[channel.symbol] = 'follows the applied loads'
            continue
        variable = channel.variable
        variables[variable] = values
        channel_of[variable] = channel
        within = not channel.constant_within_series(points.series)
        if not within:
            series_level.add(variable)
        if channel.kind == 'temperature':
            family = temperature_family(outputs_names, variable)
            if not within:
                lone = {variable, f'{variable}^2'}
                family = CandidateFamily(
                    'temperature',
                    tuple(g for g in family.groups if not set(g) & lone),
                    family.max_groups,
                    {},
                )
        else:
            family = channel_family(outputs_names, variable, within)
        families.append((family, variable))
    families = [(without_base_terms(f, base), v) for f, v in families]

    columns = _Columns(points, variables)

    def design(terms: Sequence[str]) -> np.ndarray:
        return np.hstack([columns(terms), -onehot])

    comp_terms = [list(base) for _ in components]
    fits: list[LeastSquares] = list(base_fits)
    search = _TableSearch(
        design,
        columns,
        points,
        series_level,
        alpha,
        alpha_crossval,
        permutations,
        np.random.default_rng(seed),
    )
    adopted: list[TableEffect] = []
    adopted_families: set[tuple[str, str | None]] = set()
    added_order: list[str] = []
    for _round in range(MAX_ROUNDS):
        best = None
        for family, family_variable in families:
            key = (family.name, family_variable)
            if key in adopted_families:
                continue
            trial = _examine(family, family_variable, comp_terms, fits, search)
            if trial is not None and (best is None or trial['score'] > best['score']):
                best = trial
        if best is None:
            break
        adopted_families.add((best['family'].name, best['variable']))
        for k, (terms, fit) in best['components'].items():
            comp_terms[k] = comp_terms[k] + list(terms)
            fits[k] = fit
            added_order += [t for t in terms if t not in added_order]
        adopted.append(_effect(best, points, channel_of))

    used = {v for t in parse_terms(added_order) for v in t.variables} if added_order else set()
    return TableDiagnosis(
        effects=tuple(adopted),
        added_terms=tuple(added_order),
        variables={k: v for k, v in variables.items() if k in used},
        channels=tuple(channel_of[v] for v in channel_of if v in used),
        examined=tuple(f.name if v is None else f'{f.name} ({v})' for f, v in families),
        skipped=skipped,
        warnings=tuple(warnings),
    )


@dataclass(frozen=True)
class _TableSearch:
    """What every examination of one table's diagnosis reads, fixed for the diagnosis."""

    design: Callable[[Sequence[str]], np.ndarray]  # term names -> (N, p) columns and -tares
    columns: _Columns  # term names -> (N, p) columns
    points: CalibrationPoints
    series_level: set[str]  # variables constant within every series
    alpha: float  # the family's level (Bonferroni over its groups)
    alpha_crossval: float  # the cross-validated σ's drop beyond chance
    permutations: int  # of the series-level permutation test
    rng: np.random.Generator  # its permutations


def _examine(
    family: CandidateFamily,
    variable,  # the channel variable the family is keyed to (None: the loads)
    comp_terms: list[list[str]],
    fits: list[LeastSquares],
    search: _TableSearch,
) -> dict | None:
    """The family's forward selection on every component, kept where the cross-validated σ
    falls beyond chance; None when no component keeps it.
    """
    design, columns, points = search.design, search.columns, search.points
    alpha, alpha_crossval = search.alpha, search.alpha_crossval
    permutations, rng = search.permutations, search.rng
    series_level = search.series_level
    components, capacity = points.load_symbols, points.capacity
    n = points.points
    series = points.series
    at_series_level = variable in series_level
    offered = {}
    for k, c in enumerate(components):
        groups = own_terms_only(family, c, _own_output(points, k), components)
        groups = tuple(g for g in groups if not set(g) & set(comp_terms[k]))
        if groups:
            offered[k] = groups
    if not offered:
        return None
    level = alpha / sum(len(g) for g in offered.values())
    passing: dict[int, tuple[tuple[str, ...], LeastSquares]] = {}
    stats: dict[int, tuple[float, float, float, float, float]] = {}
    score = 0.0
    for k, groups in offered.items():
        names = list(dict.fromkeys(t for g in groups for t in g))
        candidates = columns(names)
        index = [tuple(names.index(t) for t in g) for g in groups]
        selection = forward_select(
            fits[k], candidates, index, alpha_per_test=level, max_groups=family.max_groups
        )
        if not selection.steps:
            continue
        added = tuple(t for step in selection.steps for t in groups[step.group])
        target = points.applied_loads[:, k]
        before_design, after_design = design(comp_terms[k]), design(comp_terms[k] + list(added))
        after = fit_columns(after_design, target)
        p_before, p_after = len(comp_terms[k]), len(comp_terms[k]) + len(added)
        if at_series_level:
            cv_before = _series_out_residuals(before_design, target, series, p_before)
            cv_after = _series_out_residuals(after_design, target, series, p_after)
            gain = fits[k].rss - after.rss
            labels = np.unique(series)
            values = np.asarray(columns([variable]))[:, 0]
            per_series = np.array([values[series == s][0] for s in labels])
            position = np.searchsorted(labels, series)
            basis, residual = fits[k].basis, fits[k].residuals
            beaten = 0
            for _ in range(permutations):
                permuted = rng.permutation(per_series)[position]
                trial = _with_variable(columns, variable, permuted, added)
                trial = trial - basis @ (basis.T @ trial)  # what the fit before cannot absorb
                coefficients = minimum_norm_solve(trial, residual).solution
                left = residual - trial @ coefficients
                beaten += fits[k].rss - float(left @ left) >= gain
            p_cv = (1 + beaten) / (1 + permutations)
            lower = float(np.mean(cv_after**2)) < float(np.mean(cv_before**2))
        else:
            cv_before, cv_after = fits[k].press_residuals, after.press_residuals
            p_cv = _drop_p(cv_before, cv_after)
            lower = float(np.mean(cv_after**2)) < float(np.mean(cv_before**2))
        if not (lower and p_cv <= alpha_crossval):
            continue
        passing[k] = (added, after)
        stats[k] = (
            float(sigma_pct_fs(fits[k].residuals, capacity[k])),
            float(sigma_pct_fs(after.residuals, capacity[k])),
            float(sigma_pct_fs(cv_before, capacity[k])),
            float(sigma_pct_fs(cv_after, capacity[k])),
            float(p_cv),
        )
        score += n * np.log(fits[k].rss / max(after.rss, 1e-300)) - len(added) * np.log(n)
    if not passing:
        return None
    return {
        'family': family,
        'variable': variable,
        'components': passing,
        'stats': stats,
        'score': score,
        'series_level': at_series_level,
    }


def _with_variable(columns: _Columns, variable: str, values: np.ndarray, terms) -> np.ndarray:
    """The design columns of `terms` with `variable` replaced by `values`."""
    names = list(columns.names)
    table = columns.values.copy()
    table[:, names.index(variable)] = values
    return design_matrix(parse_terms(list(terms)), as_variables(tuple(names), table), columns.n)


def _effect(best: dict, points: CalibrationPoints, channel_of) -> TableEffect:
    components = points.load_symbols
    family = best['family']
    names = [components[k] for k in best['components']]
    terms = tuple(dict.fromkeys(t for added, _ in best['components'].values() for t in added))
    stats = {components[k]: v for k, v in best['stats'].items()}
    channel = channel_of.get(best['variable']) if best['variable'] else None
    how = (
        'whole series left out, tested against the channel permuted among the series'
        if best['series_level']
        else 'leave-one-out, Wilcoxon signed-rank'
    )
    parts = [
        f'{c} σ {s[0]:.3g} → {s[1]:.3g} %, cross-validated {s[2]:.3g} → {s[3]:.3g} % '
        f'(p = {s[4]:.1g})'
        for c, s in stats.items()
    ]
    what = {
        'temperature': f'residual follows temperature channel {channel.symbol if channel else ""}',
        'channel': f'residual follows channel {channel.symbol if channel else ""}',
        'hysteresis': 'residual depends on the load direction within a series',
        'zero_drift': 'residual follows the point order in series returning to earlier loads',
        'bidirectional': 'sensitivity differs with the sign of the load',
    }[family.name]
    return TableEffect(
        name=family.name,
        components=tuple(names),
        evidence=f'{what}: adding {", ".join(terms)}: ' + '; '.join(parts) + f' ({how})',
        terms=terms,
        channel=channel.symbol if channel else None,
        sigma_before_pct_fs={c: s[0] for c, s in stats.items()},
        sigma_after_pct_fs={c: s[1] for c, s in stats.items()},
        crossval_before_pct_fs={c: s[2] for c, s in stats.items()},
        crossval_after_pct_fs={c: s[3] for c, s in stats.items()},
        crossval_p={c: s[4] for c, s in stats.items()},
    )
