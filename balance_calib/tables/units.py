"""Units a calibration table may name, and their factor to the package's internal units.

Loads go to SI (N, N·m). Bridge outputs go to mV when the table gives volts, and to mV/V when it
gives a ratio to the excitation (microV/V, mV/V): without the excitation voltage a ratio cannot
become mV, so a calibration fitted from such a table states `output_unit: mV/V` and the live raw
outputs must be ratios too (or `balance-calib fit --excitation-v` turns them into mV).
"""
from __future__ import annotations

from ..units import STANDARD_GRAVITY_M_S2

LBF_N = 4.4482216152605            # avoirdupois pound-force (exact by definition)
INCH_M = 0.0254

# unit as written (lower case, blanks removed) -> (factor to internal, internal unit, kind)
_UNITS = {
    'n': (1.0, 'N', 'force'),
    'kn': (1000.0, 'N', 'force'),
    'lbs': (LBF_N, 'N', 'force'), 'lb': (LBF_N, 'N', 'force'), 'lbf': (LBF_N, 'N', 'force'),
    'kgf': (STANDARD_GRAVITY_M_S2, 'N', 'force'), 'kg': (STANDARD_GRAVITY_M_S2, 'N', 'force'),
    'n-m': (1.0, 'N·m', 'moment'), 'nm': (1.0, 'N·m', 'moment'), 'n·m': (1.0, 'N·m', 'moment'),
    'n*m': (1.0, 'N·m', 'moment'), 'n.m': (1.0, 'N·m', 'moment'),
    'in-lbs': (LBF_N * INCH_M, 'N·m', 'moment'), 'in-lb': (LBF_N * INCH_M, 'N·m', 'moment'),
    'in-lbf': (LBF_N * INCH_M, 'N·m', 'moment'), 'inch-lbs': (LBF_N * INCH_M, 'N·m', 'moment'),
    'ft-lbs': (LBF_N * 12 * INCH_M, 'N·m', 'moment'), 'ft-lb': (LBF_N * 12 * INCH_M, 'N·m', 'moment'),
    'kgf-m': (STANDARD_GRAVITY_M_S2, 'N·m', 'moment'), 'kgf·m': (STANDARD_GRAVITY_M_S2, 'N·m', 'moment'),
    'kgfm': (STANDARD_GRAVITY_M_S2, 'N·m', 'moment'),
    'mv': (1.0, 'mV', 'output'), 'microv': (1e-3, 'mV', 'output'), 'uv': (1e-3, 'mV', 'output'),
    'µv': (1e-3, 'mV', 'output'), 'v': (1e3, 'mV', 'output'),
    'mv/v': (1.0, 'mV/V', 'output'), 'microv/v': (1e-3, 'mV/V', 'output'), 'uv/v': (1e-3, 'mV/V', 'output'),
    'µv/v': (1e-3, 'mV/V', 'output'), 'v/v': (1e3, 'mV/V', 'output'),
    'degc': (1.0, 'degC', 'other'), 'degf': (1.0, 'degF', 'other'), 'k': (1.0, 'K', 'other'),
    '-': (1.0, '-', 'other'), 'none': (1.0, '-', 'other'), 's': (1.0, 's', 'other'),
}


def unit_factor(unit: str) -> tuple[float, str, str] | None:
    """(factor to internal unit, internal unit, kind) of a unit as a table writes it, or None."""
    return _UNITS.get(unit.strip().replace(' ', '').lower())


def is_load_unit(unit: str) -> bool:
    found = unit_factor(unit)
    return found is not None and found[2] in ('force', 'moment')


def is_output_unit(unit: str) -> bool:
    found = unit_factor(unit)
    return found is not None and found[2] == 'output'
