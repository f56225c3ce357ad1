"""Units a calibration table may name, and their factor to the package's internal units.

Loads go to SI (N, N·m). Bridge outputs go to mV when the table gives volts, and to mV/V when it
gives a ratio to the excitation (microV/V, mV/V): without the excitation voltage a ratio cannot
become mV, so a calibration fitted from such a table states `output_unit: mV/V` and the live raw
outputs must be ratios too (or `balance-calib fit --excitation-v` turns them into mV). Raw ADC
`counts` and dimensionless `-` outputs cannot become volts at all (the gain and the reference are
not in the table): the fit then works in those output units, and the calibration says so.

The factors are built from the exact definitions in `balance_calib.units` (1 lb = 0.45359237 kg,
1 in = 0.0254 m, g_n = 9.80665 m/s²), the one source of them.
"""

from __future__ import annotations

from ..units import METRE_PER_INCH, NEWTON_PER_LBF, STANDARD_GRAVITY_M_S2

NEWTON_PER_OZF = NEWTON_PER_LBF / 16.0  # avoirdupois ounce-force: 1/16 lbf
NEWTON_PER_GF = STANDARD_GRAVITY_M_S2 * 1e-3  # gram-force

# Output units that are not voltages: the fit keeps them as they are (factor 1).
NON_VOLTAGE_OUTPUT_UNITS = ('counts', '-')


def _entries(kind: str, internal: str, factor: float, *spellings: str) -> dict:
    return dict.fromkeys(spellings, (factor, internal, kind))


# unit as written (lower case, blanks removed) -> (factor to internal, internal unit, kind)
_UNITS = {
    **_entries('force', 'N', 1.0, 'n'),
    **_entries('force', 'N', 1000.0, 'kn'),
    **_entries('force', 'N', NEWTON_PER_LBF, 'lbs', 'lb', 'lbf'),
    **_entries('force', 'N', STANDARD_GRAVITY_M_S2, 'kgf', 'kg'),
    **_entries('force', 'N', NEWTON_PER_GF, 'gf', 'g'),
    **_entries('force', 'N', NEWTON_PER_OZF, 'ozf', 'oz'),
    **_entries('moment', 'N·m', 1.0, 'n-m', 'nm', 'n·m', 'n*m', 'n.m'),
    **_entries('moment', 'N·m', 1000.0, 'kn-m', 'knm', 'kn·m', 'kn*m', 'kn.m'),
    **_entries('moment', 'N·m', 1e-3, 'n-mm', 'nmm', 'n·mm', 'n*mm', 'n.mm'),
    **_entries(
        'moment', 'N·m', NEWTON_PER_LBF * METRE_PER_INCH, 'in-lbs', 'in-lb', 'in-lbf', 'inch-lbs'
    ),
    **_entries('moment', 'N·m', NEWTON_PER_LBF * 12 * METRE_PER_INCH, 'ft-lbs', 'ft-lb'),
    **_entries(
        'moment', 'N·m', NEWTON_PER_OZF * METRE_PER_INCH, 'in-ozf', 'in-oz', 'ozf-in', 'oz-in'
    ),
    **_entries('moment', 'N·m', STANDARD_GRAVITY_M_S2, 'kgf-m', 'kgf·m', 'kgfm'),
    **_entries('output', 'mV', 1.0, 'mv'),
    **_entries('output', 'mV', 1e-3, 'microv', 'uv', 'µv'),
    **_entries('output', 'mV', 1e3, 'v'),
    **_entries('output', 'mV/V', 1.0, 'mv/v'),
    **_entries('output', 'mV/V', 1e-3, 'microv/v', 'uv/v', 'µv/v'),
    **_entries('output', 'mV/V', 1e3, 'v/v'),
    **_entries('output', 'counts', 1.0, 'counts', 'count', 'cts', 'adc'),
    **_entries('output', '-', 1.0, '-'),
    **_entries('other', 'degC', 1.0, 'degc'),
    **_entries('other', 'degF', 1.0, 'degf'),
    **_entries('other', 'K', 1.0, 'k'),
    **_entries('other', '-', 1.0, 'none'),
    **_entries('other', 's', 1.0, 's'),
}

# How the known units are listed in a message (one spelling each, as tables write them).
_LISTED = {
    'load': (
        'N',
        'kN',
        'lbs',
        'kgf',
        'gf',
        'g',
        'ozf',
        'N-m',
        'kN-m',
        'N-mm',
        'in-lbs',
        'ft-lbs',
        'in-ozf',
        'kgf-m',
    ),
    'output': ('mV', 'microV', 'V', 'mV/V', 'microV/V', 'V/V', 'counts', '-'),
    'other channel': ('degC', 'degF', 'K', 'none', 's'),
}


def unit_factor(unit: str) -> tuple[float, str, str] | None:
    """(factor to internal unit, internal unit, kind) of a unit as a table writes it, or None.

    kind is 'force', 'moment', 'output' (a bridge signal) or 'other' (an extra channel).
    """
    return _UNITS.get(unit.strip().replace(' ', '').lower())


def known_unit(unit: str) -> tuple[float, str, str]:
    """unit_factor() of a unit already checked (the table reader refuses unknown ones)."""
    found = unit_factor(unit)
    if found is None:
        raise ValueError(f'unknown unit {unit!r}')
    return found


def is_load_unit(unit: str) -> bool:
    found = unit_factor(unit)
    return found is not None and found[2] in ('force', 'moment')


def is_output_unit(unit: str) -> bool:
    found = unit_factor(unit)
    return found is not None and found[2] == 'output'


def known_units() -> str:
    """The known units, by kind, for a one-line message: 'loads N, kN, …; outputs mV, …; …'."""
    return '; '.join(f'{kind}s {", ".join(units)}' for kind, units in _LISTED.items())
