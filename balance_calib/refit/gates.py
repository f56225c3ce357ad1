"""Acceptance gates: a refit is adopted only when its data and its result look like a calibration.

As AIAA R-091 practice checks a calibration before it is used, every refit is checked before
calibration.yaml is written or swapped in:

    output_range       the bridge outputs span about their rated outputs (the schedule loads the
                       balance to its capacity): outputs recorded in V, or µV, cannot pass
    sigma              σ of the base model per component (TM-663 eqs. (44)-(49)) within its limit
    outliers           no load point whose loads disagree with its outputs (leave-one-out residual
                       beyond k robust σ): a weight typo, a misplaced marker, a clipped point;
                       after the diagnosis, against the adopted model; on a component where
                       the diagnosis found something, a point within the threshold after the
                       effect named there (adopted, or named as fitting part of the structure),
                       or that the campaign's structure predicts from the other points, is
                       explained, not refused (diagnosis/coherence.py)
    sensitivity        fitted linear sensitivities (N per mV) near the balance's nominal ones
                       (config Table 10/14 linear matrix, else capacity / rated output): loads
                       recorded in kgf or the wrong --balance cannot pass
    active_calibration ... and near the active calibration's, when one is given
    zero_points        consecutive zero points of one block agree (TM-663 §5(4)): a block whose
                       zero points differ by the body's weight turned is two orientations under
                       one /calibration/gravity message (one lost or never sent)
    body_weight        calibration body weight positive and near its declaration
    capacity           applied loads within the rated loads
    clipping           no bridge flat-topped at one value (an amplifier or ADC at its limit)
    marker_order       applied_load stamps in the order they were recorded
    schedule           the load points found are the schedule's (Appendix A/B, or the one the
                       campaign ran): at most a share of its points missing in all, and of the
                       points loading each component (markers dropped, a session lost)

Limits come from the balance config's `acceptance:` mapping, with the defaults below. Each gate
gives one line a person can act on. A failed gate raises nothing here: the pipeline decides
(RefitError, unless forced).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from ..config import BalanceConfig, ConfigError, LoadSchedule
from ..fit.crossval import press_residuals
from ..model.inverse import linear_part

DEFAULT_SIGMA_LIMIT_PCT_FS = 0.25  # per component, or 3x the memo's Table 17 σ if larger
DEFAULT_OUTLIER_ROBUST_SIGMAS = 7.0  # leave-one-out residual / (1.4826 MAD)
DEFAULT_OUTLIER_FLOOR_PCT_FS = 0.05  # and at least this far off
DEFAULT_SENSITIVITY_NOMINAL_TOLERANCE = 0.15
DEFAULT_SENSITIVITY_ACTIVE_TOLERANCE = 0.05
DEFAULT_BODY_WEIGHT_TOLERANCE = 0.10
DEFAULT_CAPACITY_MARGIN = 0.05
DEFAULT_ZERO_SHIFT_PCT_FS = 2.0  # between consecutive zero points of one block
DEFAULT_MISSING_POINTS_SHARE = 0.10  # of the schedule's points, at most
DEFAULT_MISSING_COMPONENT_SHARE = 0.20  # of the scheduled points loading one component, at most
SCHEDULE_MATCH_PCT_FS = 0.5  # a found point is a scheduled one: every load this close


@dataclass(frozen=True)
class AcceptanceLimits:
    sigma_limit_pct_fs: Mapping[str, float]
    outlier_robust_sigmas: float = DEFAULT_OUTLIER_ROBUST_SIGMAS
    outlier_floor_pct_fs: float = DEFAULT_OUTLIER_FLOOR_PCT_FS
    sensitivity_nominal_tolerance: float = DEFAULT_SENSITIVITY_NOMINAL_TOLERANCE
    sensitivity_active_tolerance: float = DEFAULT_SENSITIVITY_ACTIVE_TOLERANCE
    body_weight_tolerance: float = DEFAULT_BODY_WEIGHT_TOLERANCE
    capacity_margin: float = DEFAULT_CAPACITY_MARGIN
    zero_shift_pct_fs: float = DEFAULT_ZERO_SHIFT_PCT_FS
    missing_points_share: float = DEFAULT_MISSING_POINTS_SHARE
    missing_component_share: float = DEFAULT_MISSING_COMPONENT_SHARE


def acceptance_limits(config: BalanceConfig, base_model: str = 'cubic') -> AcceptanceLimits:
    """The config's `acceptance:` limits over the defaults; ConfigError naming a bad key."""
    where = f'{config.path or config.name}: acceptance'
    data = config.raw.get('acceptance') or {}
    if not isinstance(data, Mapping):
        raise ConfigError(f'{where}: expected a mapping')
    memo = config.table17_sigma_pct_fs.get(base_model, {}) if config.table17_sigma_pct_fs else {}
    sigma = {
        c: max(DEFAULT_SIGMA_LIMIT_PCT_FS, 3.0 * float(memo.get(c, 0.0)))
        for c in config.components
    }
    given = data.get('sigma_limit_pct_fs', {})
    if isinstance(given, (int, float)):
        given = dict.fromkeys(config.components, given)
    if not isinstance(given, Mapping):
        raise ConfigError(
            f'{where}.sigma_limit_pct_fs: expected a number or a mapping per component'
        )
    for component, value in given.items():
        if component not in config.components:
            raise ConfigError(f'{where}.sigma_limit_pct_fs: unknown component {component!r}')
        sigma[component] = _positive(value, f'{where}.sigma_limit_pct_fs.{component}')
    numbers = {}
    for key in (
        'outlier_robust_sigmas',
        'outlier_floor_pct_fs',
        'sensitivity_nominal_tolerance',
        'sensitivity_active_tolerance',
        'body_weight_tolerance',
        'capacity_margin',
        'zero_shift_pct_fs',
        'missing_points_share',
        'missing_component_share',
    ):
        if key in data:
            numbers[key] = _positive(data[key], f'{where}.{key}')
    unknown = set(data) - {'sigma_limit_pct_fs', *AcceptanceLimits.__dataclass_fields__}
    if unknown:
        raise ConfigError(f'{where}: unknown key(s) {", ".join(sorted(unknown))}')
    return AcceptanceLimits(sigma, **numbers)


def _positive(value, where: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f'{where}: {value!r} is not a number') from None
    if not np.isfinite(number) or number <= 0:
        raise ConfigError(f'{where}: must be a positive finite number, not {value!r}')
    return number


@dataclass(frozen=True)
class Gate:
    name: str
    passed: bool
    reason: str  # one line
    details: Mapping[str, Any] = field(default_factory=dict)


def failed(gates: Sequence[Gate]) -> list[Gate]:
    return [g for g in gates if not g.passed]


def gates_report(gates: Sequence[Gate], *, forced: bool) -> dict:
    """report.json's `acceptance` entry."""
    return {
        'passed': not failed(gates),
        'forced': bool(forced and failed(gates)),
        'gates': [
            {'name': g.name, 'passed': g.passed, 'reason': g.reason, **_plain(g.details)}
            for g in gates
        ],
    }


def _plain(value):
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return round(float(value), 6) if np.isfinite(value) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    return value


# -- the gates ------------------------------------------------------------------------------------


def data_gates(
    config: BalanceConfig,
    points,
    reduction,
    fits,
    cut=None,
    active=None,
    limits: AcceptanceLimits | None = None,
    schedule: LoadSchedule | None = None,
) -> list[Gate]:
    """Gates on the data and the sensitivities, before the (slow) diagnosis. points: LoadPoints;
    fits: order -> ModelFit; cut: load_points.CutSummary or None; active: Calibration or None;
    schedule: the one the campaign ran (None: the balance config's own).
    """
    limits = limits or acceptance_limits(config)
    gates = [
        _sensitivity_gate(config, fits, limits),
        schedule_gate(
            config, points, schedule if schedule is not None else config.schedule, limits
        ),
    ]
    if active is not None:
        gates.append(_active_gate(config, fits, active, limits))
    gates += [
        _zero_gate(config, points, reduction, limits),
        _body_gate(config, reduction, limits),
        _capacity_gate(config, points, limits),
    ]
    if cut is not None:
        gates += [_clipping_gate(cut), _marker_gate(cut)]
    return gates


def fit_gates(
    config: BalanceConfig,
    points,
    sigma_pct_fs: Mapping[str, float],
    residuals: np.ndarray,
    press: np.ndarray,
    limits: AcceptanceLimits | None = None,
    what: str = 'base model',
    unexplained: Mapping[str, str] | None = None,
    structure=None,
) -> list[Gate]:
    """σ and outlier gates on the model to be adopted: its σ (% FS), residuals and leave-one-out
    residuals (P, 6) N, N·m. unexplained: component -> what the diagnosis's unexplained structure
    there tracks (the outlier gate then names it as a cause besides a weight or marker error).
    structure: diagnosis.coherence.CampaignStructure or None; a flagged point that the campaign's
    structure on a component the diagnosis found something on predicts from the other points is
    not an outlier (it is reported as explained).
    """
    limits = limits or acceptance_limits(config)
    return [
        _sigma_gate(config, sigma_pct_fs, limits, what),
        _outlier_gate(
            config, points, residuals, press, limits, what, unexplained or {}, structure
        ),
    ]


def base_fit_arrays(reduction, base_fit) -> tuple[np.ndarray, np.ndarray]:
    """(residuals, leave-one-out residuals) of a ModelFit on the corrected data."""
    design = base_fit.fit.model.design(reduction.corrected.bridge_outputs_mv)
    return base_fit.fit.residuals, press_residuals(design, base_fit.fit.residuals)


def evaluate_gates(
    config: BalanceConfig,
    points,
    reduction,
    fits,
    base_model: str,
    cut=None,
    active=None,
    limits: AcceptanceLimits | None = None,
    schedule: LoadSchedule | None = None,
) -> list[Gate]:
    """All gates, σ and outliers on the base model (no diagnosis)."""
    limits = limits or acceptance_limits(config, base_model)
    residuals, press = base_fit_arrays(reduction, fits[base_model])
    return fit_gates(
        config, points, fits[base_model].sigma_pct_fs, residuals, press, limits
    ) + data_gates(config, points, reduction, fits, cut, active, limits, schedule)


OUTPUT_RANGE = (0.05, 20.0)  # largest |zeroed output| / rated output, per bridge


def output_range_gate(config: BalanceConfig, reduction) -> Gate:
    """Before any fit: do the outputs have the size the balance's rated outputs say?"""
    zeroed = np.abs(reduction.zero.zeroed_outputs_mv)
    with np.errstate(invalid='ignore'):
        largest = np.nanmax(np.where(np.isfinite(zeroed), zeroed, np.nan), axis=0)
    ratio = largest / np.abs(config.rated_output_mv)
    details = {'largest_over_rated': dict(zip(config.bridge_outputs, ratio))}
    low, high = OUTPUT_RANGE
    bad = [i for i, r in enumerate(ratio) if not (low <= r <= high)]
    if bad:
        text = ', '.join(
            f'{config.bridge_outputs[i]} {largest[i]:.3g} mV of {config.rated_output_mv[i]:.4g}'
            for i in bad
        )
        hint = (
            '; recorded in V instead of mV?'
            if np.all(ratio[bad] < low)
            else '; recorded in µV instead of mV?'
            if np.all(ratio[bad] > high)
            else ''
        )
        return Gate(
            'output_range',
            False,
            f'bridge outputs outside {low:g}-{high:g}x their rated outputs '
            f'(largest vs rated: {text}){hint}',
            details,
        )
    return Gate(
        'output_range',
        True,
        f'bridge outputs reach {ratio.min():.2f}-{ratio.max():.2f}x their rated outputs',
        details,
    )


def _sigma_gate(config, sigma, limits, what) -> Gate:
    over = [c for c in config.components if not (sigma[c] <= limits.sigma_limit_pct_fs[c])]
    details = {
        'sigma_pct_fs': dict(sigma),
        'limit_pct_fs': dict(limits.sigma_limit_pct_fs),
        'model': what,
    }
    if over:
        text = ', '.join(
            f'{c} {sigma[c]:.3g} % FS > {limits.sigma_limit_pct_fs[c]:.3g}' for c in over
        )
        return Gate('sigma', False, f'σ of the {what} beyond its limit: {text}', details)
    worst = max(config.components, key=lambda c: sigma[c] / limits.sigma_limit_pct_fs[c])
    return Gate(
        'sigma',
        True,
        f'σ of the {what} within limits (closest: {worst} {sigma[worst]:.3g} of '
        f'{limits.sigma_limit_pct_fs[worst]:.3g} % FS)',
        details,
    )


def standardized_press(
    residuals: np.ndarray, press: np.ndarray, capacity: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Leave-one-out residuals in % of capacity, as they are and standardised.

    residuals, press (N, k) in-sample and leave-one-out residuals, N or N·m; capacity (k,).
    Returns (press_pct, standardized), both (N, k) in % of capacity: standardized is
    press · sqrt(1 - h) = press · sqrt(r / press), the same variance for every point whatever
    its leverage h.
    """
    press_pct = press / capacity * 100.0
    with np.errstate(divide='ignore', invalid='ignore'):
        scale = np.sqrt(np.clip(np.where(press != 0, residuals / press, 1.0), 0.0, 1.0))
    return press_pct, press_pct * scale


def robust_sigma(
    standardized: np.ndarray, loaded: np.ndarray, *, tail_quantile: bool = False
) -> np.ndarray:
    """(k,) robust σ of standardised residuals (N, k): 1.4826 MAD over the loaded points (N,)
    bool, or over all points when fewer than 10 are loaded (zero points carry almost no residual
    after TM-663 §5(4) and would shrink the scale). tail_quantile: at least the 90 % point of
    |residual - median| / 1.6449 as well (wide-tailed mixtures of load levels).
    """
    basis = standardized[loaded] if np.count_nonzero(loaded) >= 10 else standardized
    spread = np.abs(basis - np.median(basis, axis=0))
    robust = 1.4826 * np.median(spread, axis=0)
    if tail_quantile:
        robust = np.maximum(robust, np.quantile(spread, 0.9, axis=0) / 1.6449)
    return robust


def worst_first(
    flagged: np.ndarray, standardized: np.ndarray, threshold: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The flagged points, the worst first, and the component each is worst in.

    flagged, standardized (N, k); threshold (k,). Returns (rows (M,), components (M,)): rows
    with any flagged component ordered by their largest |standardized| / threshold (a NaN counts
    as infinitely far), and the index of that component.
    """
    rows = np.flatnonzero(np.any(flagged, axis=1))
    excess = np.nan_to_num(np.abs(standardized) / threshold, nan=np.inf)
    severity = np.max(np.where(flagged, excess, 0.0), axis=1)
    rows = rows[np.argsort(-severity[rows], kind='stable')]
    if not rows.size:
        return rows, np.zeros(0, dtype=int)
    ratio = np.where(flagged[rows], np.abs(standardized[rows]) / threshold, -np.inf)
    return rows, np.nanargmax(ratio, axis=1)


def _outlier_gate(
    config, points, residuals, press, limits, what, unexplained=None, structure=None
) -> Gate:
    press_pct, standardized = standardized_press(residuals, press, config.capacity)
    robust = robust_sigma(standardized, ~points.is_zero_point)
    threshold = np.maximum(limits.outlier_robust_sigmas * robust, limits.outlier_floor_pct_fs)
    finite = np.all(np.isfinite(standardized), axis=1)
    flagged = (np.abs(standardized) > threshold) | ~finite[:, None]
    explained = _explained_by_structure(config, standardized, flagged, threshold, structure)
    flagged &= ~explained
    rows, worst = worst_first(flagged, standardized, threshold)
    entries = []
    for i, k in zip(rows[:20], worst[:20]):
        entries.append(
            {
                'point': int(points.label[i]),
                'orientation': int(points.orientation[i]),
                'component': config.components[k],
                'residual_pct_fs': float(press_pct[i, k]),
                'robust_sigmas': float(abs(standardized[i, k]) / max(robust[k], 1e-12)),
                'applied_load': [float(x) for x in points.applied_loads[i]],
            }
        )
    with np.errstate(divide='ignore', invalid='ignore'):
        largest = float(np.nanmax(np.abs(standardized) / np.maximum(robust, 1e-12)))
    details = {
        'threshold_pct_fs': dict(zip(config.components, threshold)),
        'points': entries,
        'count': int(len(rows)),
        'largest_robust_sigmas': largest,
        'model': what,
    }
    coherent = _explained_text(config, points, explained, structure)
    if coherent:
        details['explained_by_structure'] = coherent[1]
    if not len(rows):
        if coherent:
            return Gate('outliers', True, f'no point wrong on its own: {coherent[0]}', details)
        return Gate(
            'outliers',
            True,
            f'no point beyond {limits.outlier_robust_sigmas:g} robust σ '
            f'(largest {largest:.1f}; leave-one-out residuals of the {what})',
            details,
        )
    first = entries[0]
    more = (
        f' and {len(rows) - 1} more (points {", ".join(str(e["point"]) for e in entries[1:6])}'
        f'{"…" if len(rows) > 6 else ""})'
        if len(rows) > 1
        else ''
    )
    cause = 'a weight, unit or marker error?'
    tracks = (unexplained or {}).get(first['component'])
    if tracks is not None:  # structure the diagnosis could not name, on the same component
        cause = (
            f'a weight, unit or marker error, or the structure the diagnosis left unexplained on '
            f'{first["component"]} (it tracks {tracks}): an effect the model lacks?'
        )
        details['unexplained_tracks'] = tracks
    besides = f'; besides, {coherent[0]}' if coherent else ''
    return Gate(
        'outliers',
        False,
        f'point {first["point"]} (I_g {first["orientation"]}): its {first["component"]} load '
        f'disagrees with its outputs by {first["residual_pct_fs"]:+.3g} % FS '
        f'({first["robust_sigmas"]:.0f} robust σ; {cause}){more}{besides}',
        details,
    )


def _explained_by_structure(config, standardized, flagged, threshold, structure) -> np.ndarray:
    """(P, 6) flagged residuals explained on components where the diagnosis adopted an effect
    or left structure unexplained: within the threshold once judged after the effect named there
    (its leave-one-out residual with the named family's terms, diagnosis/coherence.py), or
    predicted within it by the campaign's structure from the other points.
    """
    explained = np.zeros_like(flagged)
    if structure is None:
        return explained
    from ..diagnosis.coherence import fit_structure

    named = _after_named(config, structure, standardized)
    for k, component in enumerate(config.components):
        if component not in structure.covered or not np.any(flagged[:, k]):
            continue
        within = np.abs(named[:, k]) <= threshold[k]
        fit = fit_structure(standardized[:, k], structure.basis, k, flagged[:, k])
        if fit.explains:
            within |= np.abs(fit.out_of_sample) <= threshold[k]
        explained[:, k] = flagged[:, k] & within
    return explained


def _after_named(config, structure, standardized) -> np.ndarray:
    """(P, 6) standardised leave-one-out residuals after the effects named on each component
    (structure.residuals_named), NaN where there are none or on a component with nothing named.
    """
    named = np.full_like(standardized, np.nan)
    residuals, press = structure.residuals_named, structure.press_named
    if residuals is None or press is None or np.shape(residuals) != np.shape(standardized):
        return named
    _, after = standardized_press(
        np.asarray(residuals, float), np.asarray(press, float), config.capacity
    )
    for k, component in enumerate(config.components):
        if component in structure.named:
            named[:, k] = after[:, k]
    return named


def _explained_text(config, points, explained, structure):
    """(one line, details) on the flagged points a structure explains, or None."""
    if structure is None or not np.any(explained):
        return None
    parts, details = [], {}
    for k, component in enumerate(config.components):
        rows = np.flatnonzero(explained[:, k])
        if len(rows):
            labels = [int(points.label[i]) for i in rows]
            details[component] = {'points': labels, 'structure': structure.covered[component]}
            listed = ', '.join(str(x) for x in labels[:5]) + ('…' if len(labels) > 5 else '')
            named = structure.named.get(component)
            if named:
                details[component]['named'] = named
            parts.append(
                f'{len(rows)} point(s) beyond the threshold on {component} '
                f'(points {listed}) follow {structure.covered[component]}, which the '
                f'other points share' + (f' and {named} fitted in part' if named else '')
            )
    return '; '.join(parts) + ' (an effect the model lacks, not a weight or marker error)', details


def _nominal_sensitivity(config) -> tuple[np.ndarray, str]:
    if 'linear' in config.matrices:
        return np.diag(linear_part(config.matrices['linear'])), "the config's linear matrix"
    return config.capacity / config.rated_output_mv, 'capacity / rated output'


def _fitted_sensitivity(fits) -> np.ndarray:
    model = fits['linear'].fit.model if 'linear' in fits else next(iter(fits.values())).fit.model
    return np.diag(linear_part(model))


def _ratio_gate(name, config, fitted, reference, tolerance, against, hint_default='') -> Gate:
    with np.errstate(divide='ignore', invalid='ignore'):
        ratio = fitted / reference
    bad = [i for i, r in enumerate(ratio) if not (abs(r - 1.0) <= tolerance)]
    details = {
        'ratio': dict(zip(config.components, ratio)),
        'tolerance': tolerance,
        'fitted_n_per_mv': dict(zip(config.components, fitted)),
    }
    if bad:
        text = ', '.join(f'{config.components[i]} ×{ratio[i]:.3g}' for i in bad)
        hint = hint_default
        if np.all(np.isfinite(ratio)) and np.allclose(ratio[bad], 1 / 9.80665, rtol=0.05):
            hint = '; loads recorded in kgf?'
        elif np.all(np.isfinite(ratio)) and np.allclose(ratio[bad], 9.80665, rtol=0.05):
            hint = '; outputs or loads off by g?'
        return Gate(
            name,
            False,
            f'sensitivities differ from {against} beyond ±{100 * tolerance:g} %: {text}{hint}',
            details,
        )
    worst = int(np.argmax(np.abs(ratio - 1)))
    return Gate(
        name,
        True,
        f'sensitivities within ±{100 * tolerance:g} % of {against} (largest: '
        f'{config.components[worst]} ×{ratio[worst]:.4f})',
        details,
    )


def _sensitivity_gate(config, fits, limits) -> Gate:
    reference, what = _nominal_sensitivity(config)
    return _ratio_gate(
        'sensitivity',
        config,
        _fitted_sensitivity(fits),
        reference,
        limits.sensitivity_nominal_tolerance,
        f"{config.name}'s nominal ones ({what})",
        '; the wrong --balance, or loads or outputs in other units?',
    )


def _active_gate(config, fits, active, limits) -> Gate:
    name = 'linear' if 'linear' in active.models else active.adopted
    try:
        reference = np.diag(linear_part(active.model(name)))
    except Exception as error:  # an active model without a linear part
        return Gate(
            'active_calibration', False, f'cannot compare with the active calibration ({error})'
        )
    if tuple(active.components) != tuple(config.components) or len(reference) != len(
        config.components
    ):
        return Gate(
            'active_calibration',
            False,
            f'the active calibration ({active.balance}) has components '
            f'{list(active.components)}, this balance {list(config.components)}',
        )
    gate = _ratio_gate(
        'active_calibration',
        config,
        _fitted_sensitivity(fits),
        reference,
        limits.sensitivity_active_tolerance,
        f'the active calibration ({active.balance})',
    )
    if gate.passed and str(active.balance).lower() != str(config.name).lower():
        return Gate(
            'active_calibration',
            False,
            f'the active calibration is of balance {active.balance}, this refit of {config.name}',
            gate.details,
        )
    return gate


def _zero_gate(config, points, reduction, limits) -> Gate:
    # consecutive zero points (in time) of one block: a maximal run of one orientation, as §5(4)
    order = np.argsort(points.times_s, kind='stable')
    orientation = np.asarray(points.orientation)[order]
    block = np.concatenate([[0], np.cumsum(orientation[1:] != orientation[:-1])])
    is_zero = points.is_zero_point[order]
    zeros, zero_blocks = order[is_zero], block[is_zero]
    same = zero_blocks[1:] == zero_blocks[:-1]
    pairs = list(zip(zeros[:-1][same].tolist(), zeros[1:][same].tolist()))
    details = {'limit_pct_fs': limits.zero_shift_pct_fs, 'pairs': len(pairs)}
    if not pairs:
        return Gate('zero_points', True, 'no block with two zero points to compare', details)
    before, after = np.array(pairs).T
    change_mv = points.outputs_mv[after] - points.outputs_mv[before]
    if 'linear' in config.matrices:
        change = change_mv @ linear_part(config.matrices['linear']).T
    else:
        change = change_mv * (config.capacity / config.rated_output_mv)
    change_pct = np.abs(change) / config.capacity * 100.0
    # noisy zero points differ more: the limit grows with their robust scatter (a turned body is
    # one pair far beyond the others, which leaves the median alone)
    scatter = (
        np.median(change_pct, axis=0) / 0.6745
        if len(change_pct) >= 5
        else np.zeros(change_pct.shape[1])
    )
    limit = np.maximum(limits.zero_shift_pct_fs, limits.outlier_robust_sigmas * scatter)
    ratio = np.nan_to_num(change_pct / limit, nan=np.inf)
    worst = np.unravel_index(int(np.argmax(ratio)), change_pct.shape)
    details['largest_pct_fs'] = float(change_pct[worst])
    details['limit_pct_fs'] = dict(zip(config.components, limit))
    if not change_pct[worst] <= limit[worst[1]]:
        b, a = before[worst[0]], after[worst[0]]
        return Gate(
            'zero_points',
            False,
            f'zero points {int(points.label[b])} and {int(points.label[a])} '
            f'(I_g {int(points.orientation[b])}) differ by {change_pct[worst]:.3g} % FS '
            f'in {config.components[worst[1]]}: the body was turned between them '
            f'without a /calibration/gravity message?',
            details,
        )
    return Gate(
        'zero_points',
        True,
        f'consecutive zero points of each block agree within {change_pct[worst]:.3g} % FS '
        f'({config.components[worst[1]]})',
        details,
    )


def _body_gate(config, reduction, limits) -> Gate:
    weight = float(reduction.body.weight_n)
    declared = float(config.calibration_body.weight_n)
    details = {
        'weight_n': weight,
        'declared_n': declared,
        'source': reduction.body_source,
        'tolerance': limits.body_weight_tolerance,
    }
    if not declared > 0:
        return Gate(
            'body_weight',
            False,
            f'declared calibration body weight {declared:g} N is not positive '
            f'({config.path or config.name}: calibration_body.weight_n)',
            details,
        )
    if not weight > 0:
        return Gate(
            'body_weight',
            False,
            f'calibration body weight {weight:.4g} N ({reduction.body_source}) '
            f'is not positive: gravity vectors or output signs reversed?',
            details,
        )
    off = weight / declared - 1.0
    if not abs(off) <= limits.body_weight_tolerance:
        return Gate(
            'body_weight',
            False,
            f'calibration body weight {weight:.4g} N ({reduction.body_source}) is '
            f'{100 * off:+.1f} % from the declared {declared:.4g} N '
            f'(limit ±{100 * limits.body_weight_tolerance:g} %)',
            details,
        )
    return Gate(
        'body_weight',
        True,
        f'body {weight:.2f} N ({reduction.body_source}), {100 * off:+.2f} % '
        f'from the declared {declared:.2f} N',
        details,
    )


def _capacity_gate(config, points, limits) -> Gate:
    fraction = np.abs(points.applied_loads) / config.capacity
    worst = np.unravel_index(int(np.argmax(fraction)), fraction.shape)
    details = {
        'max_fraction_of_capacity': dict(zip(config.components, fraction.max(axis=0))),
        'margin': limits.capacity_margin,
    }
    if not fraction[worst] <= 1.0 + limits.capacity_margin:
        count = int(np.count_nonzero(np.any(fraction > 1.0 + limits.capacity_margin, axis=1)))
        return Gate(
            'capacity',
            False,
            f'point {int(points.label[worst[0]])}: applied {config.components[worst[1]]} '
            f'{points.applied_loads[worst]:.4g} is {100 * fraction[worst]:.0f} % of '
            f'capacity ({count} point(s) beyond {100 * (1 + limits.capacity_margin):g} %; '
            f'wrong units or wrong --balance?)',
            details,
        )
    return Gate(
        'capacity',
        True,
        f'applied loads within capacity (largest {100 * fraction[worst]:.1f} %, '
        f'{config.components[worst[1]]})',
        details,
    )


def _clipping_gate(cut) -> Gate:
    if cut.clipped:
        bridge, value, samples, npoints = cut.clipped[0]
        return Gate(
            'clipping',
            False,
            f'bridge {bridge} is flat-topped at {value:.6g} mV in {samples} samples of '
            f'{npoints} points: its amplifier or ADC clipped',
            {'clipped': [list(c) for c in cut.clipped]},
        )
    return Gate('clipping', True, 'no bridge flat-topped at its extremes')


def _marker_gate(cut) -> Gate:
    details = {
        'out_of_order': cut.markers_out_of_order,
        'duplicate_stamps': cut.duplicate_marker_stamps,
    }
    if cut.markers_out_of_order:
        return Gate(
            'marker_order',
            False,
            f'applied_load message {cut.first_marker_out_of_order + 1} is stamped '
            f'before the one recorded ahead of it ({cut.markers_out_of_order} '
            f'marker(s) out of time order): points cannot be trusted',
            details,
        )
    return Gate('marker_order', True, 'applied_load markers in time order', details)


def match_schedule(
    applied_loads: np.ndarray,
    orientation: np.ndarray,
    schedule: LoadSchedule,
    tolerance: np.ndarray,
) -> np.ndarray:
    """Which schedule row each found load point is, or -1 for a point the schedule does not have.

    Parameters
    ----------
    applied_loads : (P, n) N, N·m, the points' applied loads (body weight excluded).
    orientation : (P,) I_g of each point.
    schedule : the schedule's N rows, loads in the same components and units.
    tolerance : (n,) N, N·m: a point is a row when every load is this close.

    Returns
    -------
    (P,) int: each schedule row is taken by one point at most (the first in the points' order),
    a row of the point's own I_g before a row of another (a schedule repeats loads at each I_g).
    """
    found = np.asarray(applied_loads, float)
    rows = np.asarray(schedule.loads, float)
    close = np.all(np.abs(found[:, None, :] - rows[None, :, :]) <= tolerance, axis=2)  # (P, N)
    same_ig = np.asarray(orientation)[:, None] == np.asarray(schedule.orientation)[None, :]
    taken = np.zeros(len(rows), bool)
    match = np.full(len(found), -1)
    for p in np.flatnonzero(close.any(axis=1)):
        for candidates in (close[p] & same_ig[p] & ~taken, close[p] & ~taken):
            if candidates.any():
                match[p] = int(np.argmax(candidates))
                taken[match[p]] = True
                break
    return match


def schedule_gate(
    config: BalanceConfig,
    points,
    schedule: LoadSchedule | None,
    limits: AcceptanceLimits | None = None,
) -> Gate:
    """The load points found against the schedule the campaign ran: count and coverage.

    A campaign that lost a share of its points (applied_load markers dropped, a session or a
    bag missing) still fits, but its calibration rests on fewer points than the schedule was
    designed with, and a component may have lost the loads that determine its terms. Refused when
    more than `missing_points_share` of the schedule's points are missing, or more than
    `missing_component_share` of the points loading one component (in either direction).

    points: LoadPoints (P,); schedule: LoadSchedule (N,) in the config's components, or None.
    """
    limits = limits or acceptance_limits(config)
    if schedule is None or len(schedule) == 0:
        return Gate('schedule', True, 'no load schedule to compare the points with')
    capacity = np.asarray(config.capacity, float)
    tolerance = SCHEDULE_MATCH_PCT_FS / 100.0 * capacity
    match = match_schedule(points.applied_loads, points.orientation, schedule, tolerance)
    expected = len(schedule)
    found = np.zeros(expected, bool)
    found[match[match >= 0]] = True
    missing = expected - int(found.sum())
    extra = int(np.count_nonzero(match < 0))
    share = missing / expected
    rows = np.asarray(schedule.loads, float)
    coverage, lost = {}, []
    for k, component in enumerate(config.components):
        entry = {}
        for sign, side in ((1.0, '+'), (-1.0, '-')):
            loading = sign * rows[:, k] > tolerance[k]
            if loading.any():
                entry[side] = [
                    int(np.count_nonzero(found & loading)),
                    int(np.count_nonzero(loading)),
                ]
        if not entry:
            continue
        got = sum(e[0] for e in entry.values())
        of = sum(e[1] for e in entry.values())
        coverage[component] = {'found': got, 'expected': of, **entry}
        short = [side for side, (g, n) in entry.items() if g == 0]
        if (of - got) / of > limits.missing_component_share or short:
            none = f' (none {component}{short[0]})' if short else ''
            lost.append(f'{component} {got} of {of}{none}')
    details = {
        'expected': expected,
        'found': expected - missing,
        'missing': missing,
        'not_in_schedule': extra,
        'missing_share': share,
        'coverage': coverage,
        'limit_share': limits.missing_points_share,
        'limit_component_share': limits.missing_component_share,
        'missing_points': [int(p) for p in np.asarray(schedule.point)[~found][:50]],
    }
    counts = (
        f'{expected - missing} of the {expected} scheduled points found ({missing} missing, '
        f'{100 * share:.0f} %'
    )
    unknown = f'; {extra} point(s) not in the schedule' if extra else ''
    if share > limits.missing_points_share or lost:
        hint = (
            '; a campaign of another schedule (--schedule FILE)?'
            if extra > missing / 2
            else '; applied_load markers or a session lost?'
        )
        coverage_text = '; lost coverage: ' + ', '.join(lost) if lost else ''
        return Gate(
            'schedule',
            False,
            f'{counts}, limit {100 * limits.missing_points_share:g} %)'
            f'{coverage_text}{unknown}{hint}',
            details,
        )
    return Gate(
        'schedule',
        True,
        f'{counts}, within {100 * limits.missing_points_share:g} %; '
        f'every component covered){unknown}',
        details,
    )
