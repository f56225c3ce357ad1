"""A run's loads from the files `coverage` reads: a CSV of loads, or the /balance/wrench a
calibrator published into bags (tunnel axes, turned back into balance axes by the installation).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Sequence

import numpy as np

from ..bags.reader import read_bags, TopicNames
from ..csv_files import csv_errors, read_csv_text, require_finite_loads
from ..tunnel_axes import Installation

WRENCH_TOPIC = '/balance/wrench'


class RunInputError(ValueError):
    """A loads file or bag that cannot be read as a run; the message names the file and row."""


def read_loads_csv(path: str | Path, components: Sequence[str]) -> np.ndarray:
    """(N, n) loads from a CSV with a header naming the components (FX,FY,FZ,MX,MY,MZ), N and N·m.

    Other columns are ignored. RunInputError for a missing column, a non-number or non-finite cell
    (row numbers count data rows from 1), or no rows at all.
    """
    path = Path(path)
    with csv_errors(path, RunInputError):
        reader = csv.reader(io.StringIO(read_csv_text(path, 'loads', RunInputError)))
        header = [h.strip() for h in next(reader, [])]
        if not header:
            raise RunInputError(f'{path}: no loads (the file is empty)')
        missing = [c for c in components if c not in header]
        if missing:
            raise RunInputError(
                f'{path}: no column {", ".join(missing)} (the header must name '
                f'{",".join(components)}, loads in N and N·m)'
            )
        columns = [header.index(c) for c in components]
        rows = []
        for number, record in enumerate(reader, start=1):
            if not any(cell.strip() for cell in record):
                continue
            try:
                values = [float(record[i]) for i in columns]
            except (ValueError, IndexError):
                raise RunInputError(
                    f'{path}: row {number}: a load is missing or not a number'
                ) from None
            require_finite_loads(values, path, number, RunInputError)
            rows.append(values)
        if not rows:
            raise RunInputError(f'{path}: no loads (only a header)')
        return np.array(rows, dtype=float)


def read_wrench_bags(
    paths: Sequence[str | Path], installation: Installation, topic: str = WRENCH_TOPIC
) -> tuple[np.ndarray, np.ndarray]:
    """(S,) stamps in s from the first sample and (S, 6) balance-axis loads of the wrenches in
    the bags.

    BagError (from bags/reader.py) names the files when the topic has no messages. Samples that are
    not finite are kept as NaN rows (their u is not computed and they are counted).
    """
    unused = '/balance_calib/coverage/unused'
    topics = TopicNames(
        raw=topic, applied_load=unused + '_a', gravity=unused + '_g', temperature=unused + '_t'
    )
    data = read_bags([Path(p) for p in paths], topics=topics, required=('raw',))
    order = np.argsort(data.raw.stamps_ns, kind='stable')
    stamps = data.raw.stamps_ns[order]
    loads = installation.from_tunnel(np.asarray(data.raw.values, dtype=float)[order])
    return (stamps - stamps[0]) / 1e9, loads


def read_raw_bags(
    paths: Sequence[str | Path], inputs: Sequence[str]
) -> tuple[np.ndarray, np.ndarray]:
    """(S,) stamps in s from the first sample and (S, n) bridge outputs (mV, in `inputs` order) of
    the /balance/raw in the bags: a run recorded without a calibrator (launchless_scripts/windon),
    whose loads are the calibration's reading of them. BagError names the files when there is
    none.
    """
    from ..units import BRIDGE_OUTPUTS

    data = read_bags([Path(p) for p in paths], required=('raw',))
    order = np.argsort(data.raw.stamps_ns, kind='stable')
    stamps = data.raw.stamps_ns[order]
    outputs = np.asarray(data.raw.values, dtype=float)[order]
    return (stamps - stamps[0]) / 1e9, outputs[:, [BRIDGE_OUTPUTS.index(v) for v in inputs]]
