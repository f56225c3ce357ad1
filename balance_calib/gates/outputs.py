"""Gates on the bridge outputs themselves, before any fit.

interfaces.md gates `output_range`, `clipping` of a refit, `channels` of a table:

    output_range  the zeroed outputs span about their rated outputs (the schedule of TM-663
                  Appendix A/B loads the balance to its capacity): outputs in V, or µV, cannot pass
    clipping      no bridge flat-topped at one value (an amplifier or ADC at its limit)
    channels      a table has as many bridge outputs as loads, none constant (a deleted or dead
                  bridge column)
"""

from __future__ import annotations

import numpy as np

from ..config import BalanceConfig
from .gate import Gate

OUTPUT_RANGE = (0.05, 20.0)  # largest |zeroed output| / rated output, per bridge
CONSTANT_FRACTION = 1e-6  # a channel whose spread is below this of its size is constant


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


def clipping_gate(cut) -> Gate:
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


def channel_gate(table, outputs: np.ndarray) -> Gate:
    """Bridge outputs (N, n_out) in the calibration's unit: enough of them, none constant."""
    symbols = table.bridge_symbols
    spread = np.ptp(outputs, axis=0) if len(outputs) else np.zeros(len(symbols))
    size = (
        np.maximum(np.max(np.abs(outputs), axis=0), 1e-300)
        if len(outputs)
        else np.ones(len(symbols))
    )
    constant = [s for s, d, m in zip(symbols, spread, size) if not d > CONSTANT_FRACTION * m]
    details = {'outputs': list(symbols), 'constant': constant}
    if len(symbols) < table.n_loads:
        return Gate(
            'channels',
            False,
            f'{len(symbols)} bridge outputs ({", ".join(symbols)}) for '
            f'{table.n_loads} loads ({", ".join(table.load_symbols)}): a bridge column '
            f'is missing',
            details,
        )
    if constant:
        return Gate(
            'channels',
            False,
            f'bridge output(s) {", ".join(constant)} constant over all {table.points} '
            f'points: a dead or disconnected bridge',
            details,
        )
    return Gate(
        'channels',
        True,
        f'{len(symbols)} bridge outputs for {table.n_loads} loads, all varying',
        details,
    )
