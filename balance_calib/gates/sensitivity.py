"""Gates on the fitted sensitivities (interfaces.md gates `sensitivity`, `active_calibration`):
loads in kgf, outputs in other units or the wrong balance cannot pass.

    sensitivity         a refit's fitted linear sensitivities (N per mV) near the balance's
                        nominal ones (the config's TM-663 Table 10/14 linear matrix, else
                        capacity / rated output)
    active_calibration  ... and near the active calibration's, when one is given
    sensitivity         a table's response at capacity of each load on the output that follows it
    (table)             against that output's rated output (the table's output capacities) where
                        the table gives them: a unit mix-up (mV/V as µV/V, kgf as N) is a factor
                        far from 1
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..model.inverse import linear_part
from .gate import Gate

RATED_OUTPUT_FACTOR = 2.0  # fitted response at capacity within [1/2, 2] x the rated output


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


def sensitivity_gate(config, fits, limits) -> Gate:
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


def active_gate(config, fits, active, limits) -> Gate:
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


def table_sensitivity_gate(
    table, rated: np.ndarray | None, response: Callable[[], np.ndarray]
) -> Gate:
    """Each load's fitted response at capacity on the output it drives most, against that
    output's rated output (NaN: unknown). response: () -> (n_loads, n_out) the outputs' change
    from zero to capacity of each load (tables/term_screen.linear_response: a linear fit of the
    outputs on the applied loads and the series), asked only when a rated output is known.
    """
    if rated is None or not np.any(np.isfinite(rated) & (np.asarray(rated) > 0)):
        return Gate(
            'sensitivity',
            True,
            'the table gives no rated outputs (output capacities): not checked',
            {},
        )
    response_at_capacity = response()
    ratios, bad = {}, []
    for v, load in enumerate(table.load_symbols):
        k = int(np.argmax(np.abs(response_at_capacity[v]) / np.maximum(np.abs(rated), 1e-300)))
        if not (np.isfinite(rated[k]) and rated[k] > 0):
            continue
        ratio = float(abs(response_at_capacity[v, k]) / rated[k])
        ratios[load] = {'output': table.bridge_symbols[k], 'ratio': ratio}
        if not (1.0 / RATED_OUTPUT_FACTOR <= ratio <= RATED_OUTPUT_FACTOR):
            bad.append(f'{load} on {table.bridge_symbols[k]} {ratio:.3g} x its rated output')
    details = {'response_at_capacity_over_rated': ratios, 'factor': RATED_OUTPUT_FACTOR}
    if bad:
        return Gate(
            'sensitivity',
            False,
            f'response at capacity against the rated outputs: '
            f'{"; ".join(bad)} (a unit or capacity error?)',
            details,
        )
    worst = max(ratios, key=lambda s: abs(np.log(ratios[s]['ratio'])), default=None)
    text = (
        f'closest to its limit: {worst} {ratios[worst]["ratio"]:.3g}'
        if worst
        else 'none comparable'
    )
    return Gate(
        'sensitivity',
        True,
        f'responses at capacity within {RATED_OUTPUT_FACTOR:g}x of the rated outputs ({text})',
        details,
    )
