"""A calibration campaign recorded as bags -> the BALFIT-style table other tools read.

The bag is read by refit's reader (refit/bag_points.py: load points, zero points §5(4),
calibration-body tare §6-7 with the tare outputs from a fitted cubic's inverse, as the refit
reduces it before its fits; no fit of the calibration, no gate, no report): the table holds the
corrected total loads (N, N·m) and the zero-corrected outputs (mV), one load series (the body
tare is already in the loads, so its fitted tare is the model's constant, nothing else) and a
natural zero of 0 at four roll angles. Fitting that table with the direct method and the
tm663-cubic terms gives the refit's cubic calibration.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from .balfit_reader import CalibrationTable
from .balfit_writer import write_table


class ExportError(ValueError):
    """The bags cannot be exported; one line naming the file and the problem."""


def corrected_table(config, corrected, name: str = '') -> CalibrationTable:
    """loads_table of corrected data (reduction.CorrectedData: loads, bridge_outputs_mv)."""
    return loads_table(config, corrected.loads, corrected.bridge_outputs_mv, name)


def loads_table(config, loads, outputs, name: str = '') -> CalibrationTable:
    """The table of corrected points: total loads (N, 6) N / N·m, outputs (N, 6) mV, one series."""
    loads = np.asarray(loads, float)
    outputs = np.asarray(outputs, float)
    n = len(loads)
    units = tuple('N' if c.startswith('F') else 'N-m' for c in config.components)
    return CalibrationTable(
        name or config.name,
        'DATA_FOR_ITERATIVE_REGRESSION_ANALYSIS',
        config.name,
        'corrected points of a recorded campaign (zero points and calibration-body tare applied)',
        tuple(config.components),
        tuple(config.bridge_outputs),
        units,
        ('mV',) * len(config.bridge_outputs),
        np.asarray(config.capacity, float),
        np.asarray(config.rated_output_mv, float),
        tuple(f'NZ-{i + 1}' for i in range(4)),
        ('Z1',) * 4,
        np.array([0.0, 90.0, 180.0, 270.0]),
        np.zeros((4, len(config.bridge_outputs))),
        tuple(f'P-{i + 1:04d}' for i in range(n)),
        np.ones(n, dtype=int),
        ('Z1',) * n,
        loads,
        outputs,
    )


def export_bags_table(bags: Sequence[str | Path], balance: str, out: Path) -> tuple[Path, int]:
    """Write the corrected points of the campaign in `bags` to `out`; returns (out, points).

    ExportError (one line naming the file) when the config or the bags cannot be read or the
    points cannot be reduced.
    """
    from ..calibration_file import ConfigError
    from ..config import load_balance_config
    from ..refit.bag_points import BagReading, read_bag_points
    from ..refit.errors import RefitError

    try:
        config = load_balance_config(balance)
        points = read_bag_points(bags, config, BagReading(tare_model='cubic'))
    except (ConfigError, RefitError) as err:
        raise ExportError(str(err)) from None
    table = loads_table(config, points.applied_loads, points.outputs)
    write_table(
        out, table, comments=[f'exported by balance-calib from {", ".join(map(str, bags))}']
    )
    return out, table.points
