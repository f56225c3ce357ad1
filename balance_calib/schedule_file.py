"""Load schedules as CSV files, the layout of TM-663's load instruction sheets (Appendices A/B).

Columns `point,executed,Ig,FX_kgf,FY_kgf,FZ_kgf,MX_kgfm,MY_kgfm,MZ_kgfm,paren_cols`, one row per
printed row, loads in kgf and kgf·m (g = 9.80665 m/s², interfaces.md). `executed` is 1 for the
points actually loaded (rows without it are all executed); `paren_cols` names, separated by `;`,
the columns printed in parentheses (by-products of the loading hardware) and may be absent. Inside,
a schedule is a `config.LoadSchedule` in N and N·m, as the balance config's own.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from .config import ConfigError, LoadSchedule
from .csv_files import csv_errors, read_csv_text, require_finite_loads
from .units import STANDARD_GRAVITY_M_S2

LOAD_COLUMNS = ('FX_kgf', 'FY_kgf', 'FZ_kgf', 'MX_kgfm', 'MY_kgfm', 'MZ_kgfm')
COLUMNS = ('point', 'executed', 'Ig') + LOAD_COLUMNS + ('paren_cols',)
REQUIRED = ('point', 'Ig') + LOAD_COLUMNS


def read_schedule_csv(path: str | Path) -> LoadSchedule:
    """The executed rows of a schedule CSV as a LoadSchedule in N and N·m.

    Raises ConfigError naming the file, the row (1 = first data row) and the column of anything
    that is not a schedule: a missing column, a non-number, a NaN, a repeated point number, an
    orientation I_g outside 1-8, no executed point at all.
    """
    path = Path(path)
    with csv_errors(path, ConfigError):
        reader = csv.DictReader(io.StringIO(read_csv_text(path, 'schedule', ConfigError)))
        header = [h.strip() for h in (reader.fieldnames or [])]
        missing = [c for c in REQUIRED if c not in header]
        if missing:
            raise ConfigError(
                f'{path}: not a load schedule: missing column(s) {", ".join(missing)} '
                f'(expected {",".join(COLUMNS)})'
            )
        points, orientations, loads, byproducts = [], [], [], []
        for number, raw in enumerate(reader, start=1):
            record = {
                (k or '').strip(): v.strip() if isinstance(v, str) else '' for k, v in raw.items()
            }
            if record.get('executed', '1') not in ('1', ''):
                if record['executed'] != '0':
                    raise ConfigError(
                        f'{path}: row {number}: executed must be 0 or 1, '
                        f'not {record["executed"]!r}'
                    )
                continue
            try:
                point = int(record['point'])
                orientation = int(record['Ig'])
                values = [float(record[c]) for c in LOAD_COLUMNS]
            except ValueError:
                bad = next(c for c in REQUIRED if not _is_number(record[c]))
                raise ConfigError(
                    f'{path}: row {number}: column {bad} is {record[bad]!r}, not a number'
                ) from None
            require_finite_loads(values, path, number, ConfigError)
            if not 1 <= orientation <= 8:
                raise ConfigError(
                    f'{path}: row {number}: I_g = {orientation}, expected 1-8 '
                    f"(TM-663's orientations)"
                )
            points.append(point)
            orientations.append(orientation)
            loads.append(values)
            byproducts.append(' '.join(c for c in record.get('paren_cols', '').split(';') if c))
        if not points:
            raise ConfigError(f'{path}: the schedule has no executed load point')
        repeated = sorted({p for p in points if points.count(p) > 1})
        if repeated:
            raise ConfigError(
                f'{path}: point number(s) {", ".join(map(str, repeated[:5]))} '
                f'appear more than once'
            )
        return LoadSchedule(
            np.array(points),
            np.array(orientations),
            np.array(loads, dtype=float) * STANDARD_GRAVITY_M_S2,
            tuple(byproducts),
        )


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def schedule_csv_text(schedule: LoadSchedule) -> str:
    """The schedule in the layout of ../data/*_schedule.csv (every row executed)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator='\n')
    writer.writerow(COLUMNS)
    in_kgf = np.asarray(schedule.loads, dtype=float) / STANDARD_GRAVITY_M_S2
    for point, orientation, loads, byproduct in zip(
        schedule.point, schedule.orientation, in_kgf, schedule.byproduct
    ):
        writer.writerow(
            [int(point), 1, int(orientation)]
            + [f'{v:.6g}' for v in loads + 0.0]
            + [';'.join(byproduct.split())]
        )
    return buffer.getvalue()


def schedule_for(config, path: str | Path, capacity_margin: float) -> LoadSchedule:
    """The schedule in a CSV file, checked against the balance it is to run on: every I_g one the
    config has a gravity direction for, every applied load within the balance's capacity plus
    capacity_margin (a fraction: the refit's capacity gate's, gates/limits.acceptance_limits).
    """
    schedule = read_schedule_csv(path)
    unknown = sorted({int(i) for i in schedule.orientation} - set(config.gravity_directions))
    if unknown:
        raise ConfigError(
            f'{path}: I_g {", ".join(map(str, unknown))} not among the '
            f'orientations of '
            f'{config.path or config.name} (gravity_directions)'
        )
    margin = float(capacity_margin)
    over = np.abs(schedule.loads) > np.asarray(config.capacity, float) * (1 + margin)
    if over.any():
        row, k = np.argwhere(over)[0]
        raise ConfigError(
            f'{path}: point {int(schedule.point[row])}: {config.components[k]} '
            f'{schedule.loads[row, k]:.6g} beyond the capacity '
            f'{config.capacity[k]:.6g} of '
            f'{config.name} (+{100 * margin:.0f} %)'
        )
    return schedule
