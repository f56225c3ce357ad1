"""balance-calib design --balance CONFIG --envelope LOADS.csv --points N [--calibration CAL.yaml]
--out DIR (interfaces.md, "Coverage of a run, and design of calibration points").
"""

from __future__ import annotations

import json
from pathlib import Path
import sys


def register(subparsers) -> None:
    from ..coverage.design import DEFAULT_COMBINED_LIMIT

    parser = subparsers.add_parser(
        'design',
        help="add combined load points to a balance's schedule for a run's loads",
        description="Keep every executed point of the balance's schedule and add at most N "
        'combined load points, chosen among loads the rig can apply (within '
        'capacity, the combined-loading limit, an orientation the schedule uses) to '
        'minimise the predicted uncertainty over the envelope (I-optimal exchange), '
        'in blocks bracketed by zero points (TM-663 §5(4)). Writes schedule.csv '
        '(layout of the Appendix A/B sheets, kgf) and design.json. With --weights the added '
        "points are loads the rig's weight set can make.",
    )
    parser.add_argument(
        '--balance', required=True, help='balance config: lmc6522, b660h or a path'
    )
    parser.add_argument(
        '--envelope',
        required=True,
        help='LOADS.csv: FX,FY,FZ,MX,MY,MZ in N and N·m, balance axes, the loads '
        "of the run (the model's weight included)",
    )
    parser.add_argument(
        '--points',
        required=True,
        type=int,
        help='at most this many load points added (≥ 1; zero points come on top)',
    )
    parser.add_argument(
        '--calibration',
        help="calibration.yaml: its base model and σ (default: the config's "
        "cubic matrix and Table 17's cubic σ)",
    )
    parser.add_argument(
        '--combined-limit',
        type=float,
        default=DEFAULT_COMBINED_LIMIT,
        help='combined-loading limit of the rig, ‖total load / capacity‖₂ '
        f'(default {DEFAULT_COMBINED_LIMIT})',
    )
    parser.add_argument(
        '--weights',
        metavar='FILE',
        help="the rig's weight set, a CSV with header name,mass_kg,count (one row per kind of "
        'weight, e.g. W20,20,4): each component of an added point is rounded to the nearest '
        'load the set makes: a force to a sum of the weights × g, a moment to such a sum at '
        'one of the lever arms the schedule hangs weights at (|M|/|F| of its rows). Default: '
        'loads rounded to 1 gf',
    )
    parser.add_argument('--out', required=True, help='output directory')
    parser.set_defaults(func=run)


def _model_and_sigma(path: str, config):
    """The base model of a calibration and its residual σ (n,), N / N·m."""
    import numpy as np

    from ..calibration_file import load_calibration
    from ..coverage.design import sigma_of
    from .errors import CommandError

    calibration = load_calibration(path)
    if str(calibration.balance).lower() != str(config.name).lower():
        raise CommandError(f'{path}: a calibration of {calibration.balance}, not of {config.name}')
    model = calibration.model(calibration.base_model)
    if getattr(model, 'form', 'direct') != 'direct':
        raise CommandError(f'{path}: model {model.name} is not a direct (TM-663) model')
    sigma = sigma_of(model)
    if sigma is None:
        sigma = (
            np.array([float(calibration.sigma_pct_fs.get(c, np.nan)) for c in config.components])
            * config.capacity
            / 100.0
        )
    if not np.all(np.isfinite(sigma)):
        raise CommandError(f'{path}: states no σ for every component')
    return model, sigma


def run(args) -> int:
    from ..calibration_file import ConfigError, write_text_atomically
    from ..config import load_balance_config
    from ..coverage.design import design_points, DesignError
    from ..coverage.run_inputs import read_loads_csv, RunInputError
    from ..coverage.weight_set import read_weight_set
    from ..model.inverse import InverseDidNotConverge
    from ..schedule_file import schedule_csv_text
    from .errors import CommandError

    if args.points < 1:
        raise CommandError(f'--points {args.points}: add at least 1 point')
    try:
        config = load_balance_config(args.balance)
        envelope = read_loads_csv(args.envelope, config.components)
        model, sigma = (
            _model_and_sigma(args.calibration, config) if args.calibration else (None, None)
        )
        weight_set = read_weight_set(args.weights) if args.weights else None
        design = design_points(
            config,
            envelope,
            args.points,
            model=model,
            sigma=sigma,
            combined_limit=args.combined_limit,
            where=str(args.envelope),
            weight_set=weight_set,
        )
    except (ConfigError, RunInputError, DesignError, InverseDidNotConverge, ValueError) as err:
        raise CommandError(' '.join(str(err).split())) from None
    summary = design.summary()
    schedule_text = schedule_csv_text(design.schedule)
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        write_text_atomically(out / 'schedule.csv', schedule_text)
        write_text_atomically(out / 'design.json', json.dumps(summary, indent=2) + '\n')
    except OSError as err:
        raise CommandError(f'{err.filename or out}: {err.strerror or err}') from None
    before = summary['predicted_u_pct_fs']['before']
    after = summary['predicted_u_pct_fs']['after']
    print(
        f'{config.name}: {summary["added"]} load points added to {len(config.schedule)} '
        f'({len(design.schedule) - len(config.schedule)} rows with their zero points)'
    )
    print('predicted u RMS over the envelope, % FS:')
    print(f'{"":8s}' + ''.join(f'{c:>9s}' for c in config.components))
    print(f'{"before":8s}' + ''.join(f'{before[c]:9.4f}' for c in config.components))
    print(f'{"after":8s}' + ''.join(f'{after[c]:9.4f}' for c in config.components))
    print(f'worst component: {summary["worst_component"]}')
    if args.weights:
        print(f'added points rounded to the loads the weights of {args.weights} make')
    for note in design.notes:
        print(f'warning: {note}', file=sys.stderr)
    print(f'schedule: {out / "schedule.csv"}')
    return 0
