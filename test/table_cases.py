"""Calibration tables generated from physical-ish responses the package does not model exactly
(tanh knees, a bending beam read by eight gauges, loads from an |x| polynomial of the outputs), for
the `fit` tests. Each returns a CalibrationTable in file units plus what the test needs to derive
its expected numbers (the injected noise).
"""

from __future__ import annotations

import csv
import io

import numpy as np

from balance_calib.tables.balfit_reader import CalibrationTable, FILE_TYPE


def table(
    name,
    loads,
    outputs,
    load_units,
    output_units,
    capacity,
    applied,
    raw,
    series,
    *,
    output_capacity=None,
    zero=None,
    point_ids=None,
) -> CalibrationTable:
    """A CalibrationTable (file units) with one natural-zero set read at four roll angles."""
    n_out = len(outputs)
    zero = np.zeros(n_out) if zero is None else np.asarray(zero, float)
    roll = np.array([0.0, 90.0, 180.0, 270.0])
    pattern = np.outer(np.cos(np.radians(roll)).round(12), np.full(n_out, 1e-3))
    n = len(applied)
    output_capacity = (
        np.full(n_out, np.nan) if output_capacity is None else np.asarray(output_capacity, float)
    )
    ids = tuple(point_ids) if point_ids is not None else tuple(f'P{i + 1:03d}' for i in range(n))
    return CalibrationTable(
        name,
        FILE_TYPE,
        name,
        'generated for the fit tests',
        tuple(loads),
        tuple(outputs),
        tuple(load_units),
        tuple(output_units),
        np.asarray(capacity, float),
        output_capacity,
        tuple(f'NZ-{i + 1}' for i in range(4)),
        ('Z1',) * 4,
        roll,
        zero[None, :] + pattern,
        ids,
        np.asarray(series, int),
        ('Z1',) * n,
        np.asarray(applied, float),
        np.asarray(raw, float) + zero[None, :],
    )


def three_component_cell(
    rng,
    *,
    series_per_axis: int = 1,
    steps: int = 5,
    noise_mvv: float = 2e-4,
    knee: float = 0.02,
    first_series: int = 1,
    span=(0.2, 1.0),
    sign: float = 1.0,
    return_tares: bool = False,
):
    """A 3-component strain-gauge cell (FX, FY, FZ in N, outputs mV/V) calibrated one axis at a
    time with deadweights: per axis `series_per_axis` fixture orientations (a series each, with the
    fixture's weight as an unknown tare), `steps` loads from 20 % to 100 % of capacity. FZ's bridge
    has a low-load knee (tanh, `knee` of rated output), a shape none of the term sets holds; the
    others a small quadratic and 1.5 % cross-talk. `span` (fractions of capacity) and `sign` set
    the loads; series numbered from `first_series`. Returns (table, noise mV/V[, tares N]).
    """
    capacity = np.array([50.0, 50.0, 200.0])
    rated = np.array([1.0, 1.0, 1.5])  # mV/V at capacity
    crosstalk = np.array([[1.0, 0.015, -0.01], [-0.012, 1.0, 0.008], [0.01, -0.015, 1.0]])
    applied, series = [], []
    label = first_series
    for axis in range(3):
        for orientation in range(series_per_axis):
            block = np.zeros((steps, 3))
            direction = sign if orientation % 2 == 0 else -sign
            block[:, axis] = direction * np.linspace(*span, steps) * capacity[axis]
            applied.append(block)
            series += [label] * steps
            label += 1
    applied = np.vstack(applied)
    series = np.array(series)
    tares = {s: rng.uniform(-0.03, 0.03, 3) * capacity for s in np.unique(series)}
    total = applied + np.array([tares[s] for s in series])
    x = total / capacity
    response = x.copy()
    response[:, 0] += 0.004 * x[:, 0] ** 2
    response[:, 1] -= 0.003 * x[:, 1] ** 2
    response[:, 2] += knee * np.tanh(x[:, 2] / 0.08)  # low-load knee of the FZ bridge
    raw = (response @ crosstalk.T) * rated + rng.normal(0, noise_mvv, response.shape)
    made = table(
        'cell3',
        ('FX', 'FY', 'FZ'),
        ('rFX', 'rFY', 'rFZ'),
        ('N',) * 3,
        ('mV/V',) * 3,
        capacity,
        applied,
        raw,
        series,
        zero=np.array([0.01, -0.02, 0.03]),
        point_ids=[f'S{s}-{i % steps + 1}' for i, s in enumerate(series)],
    )
    return (made, noise_mvv, tares) if return_tares else (made, noise_mvv)


def eight_channel_sensor(rng, *, poses: int = 60, noise: float = 3e-4):
    """A six-component sensor read by eight strain-gauge bridges (a Stewart-like cell: every
    bridge sees a mix of all six loads), calibrated on `poses` random poses, all six loads at once
    up to 80 % of capacity, two series (two mounting adapters, a tare each). The bridges respond
    with a saturating strain (x - 0.05 x^3 + 0.02 x |x| of the mixed strain x), which no term set
    holds exactly. Returns (table, noise as a fraction of the rated output).
    """
    loads = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')
    capacity = np.array([500.0, 500.0, 1000.0, 40.0, 40.0, 30.0])
    mixing = rng.normal(0, 1, (8, 6))
    mixing /= np.linalg.norm(mixing, axis=1, keepdims=True)
    applied = rng.uniform(-0.8, 0.8, (poses, 6)) * capacity
    series = np.where(np.arange(poses) < poses // 2, 1, 2)
    tares = {1: rng.uniform(-0.02, 0.02, 6) * capacity, 2: rng.uniform(-0.02, 0.02, 6) * capacity}
    total = applied + np.array([tares[s] for s in series])
    strain = (total / capacity) @ mixing.T
    raw = 2.0 * (strain - 0.05 * strain**3 + 0.02 * strain * np.abs(strain))
    raw = raw + rng.normal(0, noise * 2.0, raw.shape)
    units = ('N', 'N', 'N', 'N-m', 'N-m', 'N-m')
    return table(
        'sensor8',
        loads,
        tuple(f'g{i + 1}' for i in range(8)),
        units,
        ('mV/V',) * 8,
        capacity,
        applied,
        raw,
        series,
    ), noise


def six_component_balance(rng, *, repeats: int = 1, noise: float = 1e-4, rated=None):
    """A six-component balance (FX..MZ in N / N-m, outputs mV/V) on a TM-663-like schedule: each
    load alone from -100 % to +100 % (11 steps, a series each) and every pair of loads at random
    in all four quadrants (12 points, a series each). Bridges: 2 % cross-talk, a small square and
    a tanh knee (0.05 % of rated), shapes the term sets hold only approximately; noise as a
    fraction of the rated output. `rated` (mV/V) is written as the output capacities.
    """
    from itertools import combinations

    capacity = np.array([400.0, 300.0, 1200.0, 60.0, 90.0, 50.0])
    rated = np.array([2.0, 1.5, 2.5, 1.8, 2.2, 1.6]) if rated is None else np.asarray(rated, float)
    rows, series, label = [], [], 1
    for _ in range(repeats):
        for v in range(6):
            block = np.zeros((11, 6))
            block[:, v] = np.linspace(-1, 1, 11)
            rows.append(block)
            series += [label] * 11
            label += 1
        for v, w in combinations(range(6), 2):
            block = np.zeros((12, 6))
            block[:, v] = rng.uniform(-1, 1, 12)
            block[:, w] = rng.uniform(-1, 1, 12)
            rows.append(block)
            series += [label] * 12
            label += 1
    applied = np.vstack(rows) * capacity
    series = np.array(series)
    tares = {s: rng.uniform(-0.02, 0.02, 6) * capacity for s in np.unique(series)}
    x = (applied + np.array([tares[s] for s in series])) / capacity
    crosstalk = np.eye(6) + rng.uniform(-0.02, 0.02, (6, 6))
    response = x + 0.002 * x**2 + 0.0005 * np.tanh(x / 0.1)
    raw = (response @ crosstalk.T) * rated + rng.normal(0, noise, x.shape) * rated
    units = ('N', 'N', 'N', 'N-m', 'N-m', 'N-m')
    return table(
        'balance6',
        ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ'),
        ('rFX', 'rFY', 'rFZ', 'rMX', 'rMY', 'rMZ'),
        units,
        ('mV/V',) * 6,
        capacity,
        applied,
        raw,
        series,
        output_capacity=rated,
    ), noise


def r091_features(u: np.ndarray) -> np.ndarray:
    """(N, 6n + 4 n(n-1)/2) R-091's term shapes of the columns of u, written out here (not the
    package's term machinery): per column u, |u|, u², u|u|, u³, |u|³; per pair a·b, |a·b|, a·|b|,
    |a|·b.
    """
    columns = []
    n = u.shape[1]
    for k in range(n):
        a = u[:, k]
        columns += [a, np.abs(a), a * a, a * np.abs(a), a**3, np.abs(a) ** 3]
    for i in range(n):
        for j in range(i + 1, n):
            a, b = u[:, i], u[:, j]
            columns += [a * b, np.abs(a * b), a * np.abs(b), np.abs(a) * b]
    return np.column_stack(columns)


def support_fractions(rng, single: int, pair: int, first_series: int = 1):
    """(fractions of capacity (N, 6), series (N,)): single-load sweeps -1..1 (a series each) and
    random pairs in all quadrants (a series each).
    """
    from itertools import combinations

    rows, series, label = [], [], first_series
    for v in range(6):
        block = np.zeros((single, 6))
        block[:, v] = np.linspace(-1, 1, single)
        rows.append(block)
        series += [label] * single
        label += 1
    for v, w in combinations(range(6), 2):
        block = np.zeros((pair, 6))
        block[:, [v, w]] = rng.uniform(-1, 1, (pair, 2))
        rows.append(block)
        series += [label] * pair
        label += 1
    return np.vstack(rows), np.array(series)


# A small table as a laboratory tool writes it: provenance comments first, quoted cells (one with
# a comma), 2 loads (lbs, in-lbs) and 2 outputs in microV/V, a temperature channel, natural zeros
# at four roll angles, a switched-off point.
HAND_TABLE = """\
"; written by some lab tool, version 3.1",,,,,,,
,,,,,,,
FILE_TYPE,DATA_FOR_ITERATIVE_REGRESSION_ANALYSIS,,,,,,
BALANCE_NAME,"MK-1, sting 2",,,,,,
DESCRIPTION,hand-made,,,,,,
; load and output symbols,,,,,,,
,,,,N1,RM,rN1,rRM,TEMP
; units,,,,,,,
,,,,lbs,in-lbs,microV/V,microV/V,degF
; capacities,,,,,,,
,,,,100,50,,,
; natural zeros,,,,,,,
";",point id,set,roll,,,,
,NZ1,A,0,,,10,-4,70
,NZ2,A,90,,,12,-6,70
,NZ3,A,180,,,14,-8,70
,NZ4,A,270,,,12,-6,70
; data for analysis,,,,,,,
,Point ID,Series,NZ set,,,,
,P1,1,A,0,0,12,-6,70
,P2,1,A,50,0,512,-6,70
";",P3,1,A,100,0,1012,-6,70
,P4,2,A,0,25,12,494,71
,P5,2,,0,-25,12,-506,71
""".replace('TEMP', 'TC').replace('N1,RM,rN1,rRM,TC', 'N1,RM,rN1,rRM,TC')


def fix_width(text):
    rows = list(csv.reader(io.StringIO(text)))
    width = max(len(r) for r in rows)
    out = io.StringIO()
    csv.writer(out, lineterminator='\n').writerows([r + [''] * (width - len(r)) for r in rows])
    return out.getvalue()
