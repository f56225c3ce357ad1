"""Bags -> calibration points: the cut, the zero points and the calibration-body tare.

`read_bag_points` reads the bags (bags/reader.py), cuts them into load points
(load_points.py), applies the zero points (§5(4)) and the calibration-body tare (§6-7) and returns
the one points value of calibration_points.py; what only a bag has (the cut, the orientation of
each point, the bags' integrity, the files) rides along as its `BagRecord`. No fit, gate or
report: `export-table` needs nothing more, and the refit (calibrate/path.py) starts from here.
With `tare_model` the tare outputs are read through that TM-663 model fitted to the points
instead of the linear eqs. (32)-(37), as the refit does before its final fits.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
import time
from typing import Callable, Sequence

import numpy as np

from ..calibration_file import ConfigError
from ..calibration_points import BagRecord, CalibrationPoints, CutSummary
from ..config import BalanceConfig
from ..model.inverse import InverseDidNotConverge
from ..reduction import LoadPoints, reduce_points, Reduction, retare_with_model
from ..zero_points import ZeroPointError
from .errors import named, RefitError, where
from .load_points import cut_load_points, LoadPointError

Progress = Callable[[str], None]

# fewer load points than this cannot calibrate a six-component balance
MIN_POINTS = 10


@dataclass(frozen=True)
class BagReading:
    """How the bags are read and reduced."""

    salvage: bool = False  # read what is intact of a damaged bag (the report says what was lost)
    estimate_body: bool = True  # the calibration body from the zero points, else the declared
    tare_model: str | None = None  # TM-663 order whose inverse gives the tare outputs
    progress: Progress | None = None
    started_s: float | None = None  # time.monotonic() when the refit began


def read_bag_points(
    bags: Sequence[str | Path], config: BalanceConfig, reading: BagReading | None = None
) -> CalibrationPoints:
    """The corrected points of a campaign recorded in `bags`; RefitError (one line naming the
    file) when the bags cannot be read, cut or reduced.
    """
    from ..bags.errors import BagError
    from ..bags.messages import SIMULATION_TOPIC
    from ..bags.reader import read_bags

    reading = reading or BagReading()
    say = reading.progress or (lambda message: None)
    paths = [Path(p) for p in bags]
    said = ['']

    def bag_progress(done: int, total: int) -> None:
        line = f'read {done}/{total} messages ({100 * done / max(total, 1):.0f} %)'
        if line != said[0]:  # the reader may report its last count twice (end of data, end of bag)
            said[0] = line
            say(line)

    try:
        bag = read_bags(
            paths,
            required=('raw', 'applied_load', 'gravity'),
            progress=bag_progress,
            salvage=reading.salvage,
            extra_topics=(SIMULATION_TOPIC,),
        )
    except BagError as err:
        raise RefitError(str(err)) from None
    for loss in bag.losses:
        say(f'salvaged: {loss}')
    source = ', '.join(str(p) for p in paths)
    try:
        load_points, cut = cut_load_points(bag, config, source=source)
    except LoadPointError as err:
        raise RefitError(str(err)) from None
    say(
        f'{cut.points} load points, {cut.samples_used} samples used, '
        f'{cut.samples_rejected_outliers} outliers and {cut.samples_rejected_nan} NaN samples '
        'rejected'
    )
    if cut.pauses_s:
        say(
            f'{len(cut.pauses_s) + 1} sessions: pauses of '
            f'{", ".join(f"{p:.0f}" for p in cut.pauses_s)} s shortened on the time axis'
        )
    simulated = bag.extra.get(SIMULATION_TOPIC)
    record = BagRecord(
        load_points,
        cut=cut,
        files=tuple(str(p) for p in paths),
        integrity={
            'salvaged': bool(reading.salvage and bag.losses),
            'lost': list(bag.losses),
            'messages_read': dict(bag.message_counts),
        },
        clock=str(simulated.messages[0].data)
        if simulated is not None and len(simulated.messages)
        else None,
        started_s=reading.started_s if reading.started_s is not None else time.monotonic(),
    )
    return reduced_points(record, config, reading)


def campaign_points(campaign) -> LoadPoints:
    """LoadPoints straight from a simulated Campaign (no bag), for the demo and tests."""
    means, times, temps = campaign.point_means()
    return LoadPoints(
        np.asarray(campaign.point),
        means,
        times,
        temps,
        np.asarray(campaign.orientation),
        campaign.gravity,
        campaign.applied_loads,
    )


def load_points_record(
    points: LoadPoints, cut: CutSummary | None = None, files: Sequence[str] = ()
) -> BagRecord:
    """A BagRecord of load points cut elsewhere (a simulation, a test), not yet reduced."""
    return BagRecord(points, cut=cut, files=tuple(str(f) for f in files))


def reduced_points(
    record: BagRecord, config: BalanceConfig, reading: BagReading | None = None
) -> CalibrationPoints:
    """Record's load points with the zero points and the calibration-body tare applied, as
    CalibrationPoints carrying the record (its reduction filled in); RefitError naming the files
    when they cannot be reduced.
    """
    reading = reading or BagReading()
    say = reading.progress or (lambda message: None)
    points, sources = record.load_points, record.files
    if len(points.label) < MIN_POINTS:
        raise RefitError(
            f'only {len(points.label)} load points: far too few to calibrate a balance'
        )
    try:
        reduction = reduce_points(points, config, estimate_body_weight=reading.estimate_body)
        say(
            f'zero points and tare applied to {len(points.label)} points '
            f'(body {reduction.body.weight_n:.2f} N, {reduction.body_source})'
        )
        corrected = reduction
        if reading.tare_model is not None:
            corrected = retare_with_model(
                reduction, _fitted(reduction, config, reading.tare_model)
            )
    except (ZeroPointError, InverseDidNotConverge, LoadPointError, ConfigError, RefitError) as err:
        raise RefitError(named(str(err), sources)) from None
    except (np.linalg.LinAlgError, FloatingPointError, ValueError) as err:
        # absurd numbers that survived the edges (a flipped exponent bit): say so, never a
        # traceback
        raise RefitError(
            f'{where(sources)}: the load points cannot be fitted ({" ".join(str(err).split())})'
        ) from None
    data = corrected.corrected
    return CalibrationPoints(
        source=where(sources) if sources else 'simulated campaign',
        point_id=tuple(str(label) for label in np.asarray(corrected.points.label).tolist()),
        load_symbols=tuple(config.components),
        output_symbols=tuple(config.bridge_outputs),
        capacity=np.asarray(config.capacity, float),
        applied_loads=np.asarray(data.loads, float),
        outputs=np.asarray(data.bridge_outputs_mv, float),
        series=np.ones(len(data.loads), dtype=int),
        times_s=np.asarray(corrected.points.times_s, float),
        gravity=np.asarray(corrected.points.gravity, float),
        bag=replace(record, reduction=reduction, config=config),
    )


def _fitted(reduction: Reduction, config: BalanceConfig, order: str):
    """The TM-663 model of `order` fitted to the corrected points (for the tare outputs)."""
    from ..fit.least_squares import fit_model, UnexcitedTermsError
    from ..model.tm663 import tm663_terms

    data = reduction.corrected
    try:
        return fit_model(
            tm663_terms(order, config.bridge_outputs),
            data.bridge_outputs_mv,
            data.loads,
            name=order,
            rated_outputs=config.rated_outputs_by_name,
            components=config.components,
            inputs=config.bridge_outputs,
        ).model
    except UnexcitedTermsError as err:
        raise RefitError(str(err)) from None
