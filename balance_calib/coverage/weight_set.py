"""A rig's set of calibration weights, and the loads it can make (`design --weights FILE`).

The weights file is a CSV with a header `name,mass_kg,count`, one row per kind of weight:

    name,mass_kg,count
    W20,20,4
    W10,10,4
    W5,5,2
    W1,1,5

A force component F can be loaded with any sum of the weights, ±(Σ nᵢ mᵢ)·g with 0 ≤ nᵢ ≤ countᵢ.
A moment is made as the balance's schedule makes it: a force's weights hung at one of the lever
arms the schedule uses (each row that loads one force and moments: arm = |M| / |F|, e.g. the
LMC6522's M_X from F_Z at 0.04 … 0.20 m); so M = ±(Σ nᵢ mᵢ)·g · arm. Each component of a point is
rounded to the nearest load so made, on its own (a simplification: the rig is taken to have the
whole set for each loading station, and a moment's weights are not shared with its force).
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np

from ..config import BalanceConfig
from ..csv_files import csv_errors, read_csv_text
from ..units import STANDARD_GRAVITY_M_S2

MASS_STEP_KG = 1e-3  # sums of masses are exact to the gram
MAX_TOTAL_MASS_KG = 1e4  # a set heavier than 10 t is a unit mistake (g for kg?)
FORCES = ('FX', 'FY', 'FZ')


class WeightSetError(ValueError):
    """A weights file that cannot be read; the message names the file and the row."""


def read_weight_set(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(masses kg (k,), counts (k,)) from a weights CSV (module docstring); WeightSetError names
    the file, the row and the column for a missing column, a non-number, a mass that is not
    positive and finite, a count that is not a whole number ≥ 0, or no weight at all.
    """
    path = Path(path)
    with csv_errors(path, WeightSetError):
        reader = csv.reader(io.StringIO(read_csv_text(path, 'weights', WeightSetError)))
        header = [h.strip() for h in next(reader, [])]
        missing = [c for c in ('name', 'mass_kg', 'count') if c not in header]
        if missing:
            raise WeightSetError(
                f'{path}: no column {", ".join(missing)} (the header must be name,mass_kg,count)'
            )
        mass_column, count_column = header.index('mass_kg'), header.index('count')
        masses, counts = [], []
        for number, record in enumerate(reader, start=1):
            if not any(cell.strip() for cell in record):
                continue
            try:
                mass = float(record[mass_column])
                count = float(record[count_column])
            except (ValueError, IndexError):
                raise WeightSetError(
                    f'{path}: row {number}: mass_kg and count must be numbers'
                ) from None
            if not (math.isfinite(mass) and mass >= MASS_STEP_KG):
                raise WeightSetError(
                    f'{path}: row {number}: mass_kg {mass:g} must be at least {MASS_STEP_KG:g}'
                )
            if not (math.isfinite(count) and count >= 0 and count == int(count)):
                raise WeightSetError(
                    f'{path}: row {number}: count {count:g} must be a whole number ≥ 0'
                )
            masses.append(mass)
            counts.append(int(count))
    masses_kg, counts_n = np.array(masses, float), np.array(counts, int)
    total = float(masses_kg @ counts_n) if len(masses_kg) else 0.0
    if total <= 0:
        raise WeightSetError(f'{path}: no weights (every count is 0, or no rows)')
    if total > MAX_TOTAL_MASS_KG:
        raise WeightSetError(
            f'{path}: {total:g} kg in all: more than {MAX_TOTAL_MASS_KG:g} kg (masses in g?)'
        )
    return masses_kg, counts_n


def achievable_masses_kg(masses_kg, counts) -> np.ndarray:
    """Every sum Σ nᵢ mᵢ (0 ≤ nᵢ ≤ countᵢ), kg, sorted, 0 included (to MASS_STEP_KG)."""
    steps = np.rint(np.asarray(masses_kg, float) / MASS_STEP_KG).astype(np.int64)
    total = int(steps @ np.asarray(counts, np.int64))
    reachable = np.zeros(total + 1, dtype=bool)
    reachable[0] = True
    for step, count in zip(steps, counts):
        for _ in range(int(count)):  # bounded knapsack, one weight at a time
            reachable[step:] |= reachable[:-step].copy()
    return np.flatnonzero(reachable) * MASS_STEP_KG


def lever_arms_m(config: BalanceConfig) -> dict[str, np.ndarray]:
    """Per moment component, the lever arms (m) the schedule hangs a force's weights at: |M|/|F|
    over the rows that load exactly one force and this moment.
    """
    loads = np.asarray(config.schedule.loads, float) if config.schedule is not None else None
    arms: dict[str, np.ndarray] = {}
    if loads is None:
        return arms
    components = list(config.components)
    forces = [components.index(c) for c in FORCES if c in components]
    for k, component in enumerate(components):
        if component in FORCES:
            continue
        found = []
        for row in loads:
            loaded = [f for f in forces if row[f] != 0.0]
            if row[k] != 0.0 and len(loaded) == 1:
                found.append(abs(row[k] / row[loaded[0]]))
        arms[component] = np.unique(np.round(found, 6))
    return arms


def round_to_weight_set(
    applied, config: BalanceConfig, masses_kg, counts, where: str = 'the weight set'
) -> tuple[np.ndarray, list[str]]:
    """(A, n) applied loads (N, N·m) rounded, each component on its own, to the nearest load the
    weight set makes (module docstring), within the component's capacity; and one line per
    component that the set cannot reach (a wanted load beyond its largest, so rounded far).
    WeightSetError when a point needs a moment the schedule makes at no lever arm.
    """
    applied = np.atleast_2d(np.asarray(applied, float))
    forces_n = achievable_masses_kg(masses_kg, counts) * STANDARD_GRAVITY_M_S2
    arms = lever_arms_m(config)
    capacity = np.asarray(config.capacity, float)
    rounded = np.empty_like(applied)
    largest = np.zeros(len(config.components))  # the largest load the set makes, per component
    for k, component in enumerate(config.components):
        magnitude = np.abs(applied[:, k])
        if component in FORCES:
            best = _nearest(forces_n[forces_n <= capacity[k]], magnitude)
            largest[k] = np.max(forces_n[forces_n <= capacity[k]])
        else:
            lever = arms.get(component, np.zeros(0))
            lever = lever[lever > 0]
            if not len(lever):
                if np.any(magnitude > 0):
                    raise WeightSetError(
                        f'{where}: the schedule of {config.name} hangs no weight at a lever arm '
                        f'for {component}: the weight set cannot make it'
                    )
                best = magnitude
                largest[k] = np.inf
            else:
                options = np.stack(
                    [
                        _nearest(forces_n[forces_n * a <= capacity[k]], magnitude / a) * a
                        for a in lever
                    ]
                )  # (arms, A)
                best = options[
                    np.abs(options - magnitude).argmin(axis=0), np.arange(len(magnitude))
                ]
                largest[k] = max(np.max(forces_n[forces_n * a <= capacity[k]]) * a for a in lever)
        rounded[:, k] = np.sign(applied[:, k]) * best
    notes = []
    beyond = np.abs(applied) > largest * (1 + 1e-9)
    for k in (int(i) for i in np.flatnonzero(beyond.any(axis=0))):
        worst = int(np.argmax(np.abs(applied[:, k])))
        unit = 'N' if config.components[k] in FORCES else 'N·m'
        notes.append(
            f'{where} makes {config.components[k]} up to {largest[k]:.6g} {unit} only: '
            f'{int(beyond[:, k].sum())} added point(s) wanted more (up to '
            f'{applied[worst, k]:.6g} {unit}) and got {largest[k]:.6g}; more weights, or fewer '
            '--points'
        )
    return rounded, notes


def _nearest(sorted_values: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """The nearest of sorted_values (ascending, 0 first) to each of wanted."""
    right = np.clip(np.searchsorted(sorted_values, wanted), 0, len(sorted_values) - 1)
    left = np.clip(right - 1, 0, len(sorted_values) - 1)
    take_left = np.abs(wanted - sorted_values[left]) <= np.abs(sorted_values[right] - wanted)
    return np.where(take_left, sorted_values[left], sorted_values[right])
