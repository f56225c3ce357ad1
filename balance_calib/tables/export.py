"""A calibration campaign recorded as bags -> the BALFIT-style table other tools read.

The bag is reduced exactly as `refit` reduces it (load points, zero points §5(4), calibration-body
tare §6-7 with the tare outputs from the fitted cubic's inverse): the table holds the corrected
total loads (N, N·m) and the zero-corrected outputs (mV), one load series (the body tare is
already in the loads, so its fitted tare is the model's constant, nothing else) and a natural zero
of 0 at four roll angles. Fitting that table with the direct method and the tm663-cubic terms gives
the refit's cubic calibration.
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
    loads = np.asarray(corrected.loads, float)
    outputs = np.asarray(corrected.bridge_outputs_mv, float)
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
    from ..bags.errors import BagError
    from ..bags.reader import read_bags
    from ..calibration_file import ConfigError
    from ..config import load_balance_config
    from ..refit.load_points import cut_load_points, LoadPointError
    from ..refit.pipeline import calibrate_points, RefitError

    try:
        config = load_balance_config(balance)
        bag = read_bags([Path(b) for b in bags], required=('raw', 'applied_load', 'gravity'))
        points, cut = cut_load_points(bag, config, source=', '.join(map(str, bags)))
        result = calibrate_points(points, config, diagnose=False, cut=cut)
    except (ConfigError, BagError, LoadPointError, RefitError) as err:
        raise ExportError(str(err)) from None
    table = corrected_table(config, result.reduction.corrected)
    write_table(
        out, table, comments=[f'exported by balance-calib from {", ".join(map(str, bags))}']
    )
    return out, table.points
