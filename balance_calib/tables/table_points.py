"""A table's points as the one points value the diagnosis takes (calibration_points.py)."""

from __future__ import annotations

import numpy as np

from ..calibration_points import (
    CalibrationPoints,
    ExtraChannel,
    temperature_in_degc,
    TEMPERATURE_UNITS,
)
from .units import unit_factor


def points_from_table(table, outputs: np.ndarray) -> CalibrationPoints:
    """The points of a CalibrationTable; `outputs` its bridge outputs as the fit takes them.

    Extra channels are read as written: the natural zero is subtracted from bridge outputs only
    (a channel's cell in a natural-zero row is its reading at that time, interfaces.md).
    """
    channels = []
    for i, symbol in enumerate(table.output_symbols):
        if i in table.bridge_columns:
            continue
        found = unit_factor(table.output_units[i])
        unit = found[1] if found is not None else table.output_units[i].strip()
        values = np.asarray(table.outputs[:, i], float)
        if unit in TEMPERATURE_UNITS:
            values = temperature_in_degc(values, unit)
        channels.append(ExtraChannel(symbol, unit, values))
    return CalibrationPoints(
        source=table.source,
        point_id=tuple(table.point_id),
        load_symbols=tuple(table.load_symbols),
        output_symbols=tuple(table.bridge_symbols),
        capacity=np.asarray(table.load_capacity_si, float),
        applied_loads=np.asarray(table.applied_loads_si, float),
        outputs=np.asarray(outputs, float),
        series=np.asarray(table.series, int),
        channels=tuple(channels),
    )


def table_calibration_points(table) -> CalibrationPoints:
    """The points of a CalibrationTable (its outputs as written) carrying the table itself, for
    calibrate/path.calibrate.
    """
    from dataclasses import replace

    return replace(points_from_table(table, table.bridge_outputs), table=table)
