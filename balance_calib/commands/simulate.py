"""balance-calib simulate: a full campaign of a simulated balance, the three models fitted,
Table 17 (the memo's numbers beside ours) and the cubic matrix in the memo's layout.
"""

from __future__ import annotations

from dataclasses import replace
import os
from pathlib import Path
import sys
from typing import cast

from .run_arguments import add_simulated_balance_arguments, SimulatedBalance

TRANSITION_SAMPLES = 2  # per load change, as a recorded campaign has them


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'simulate',
        help='simulate a calibration campaign and fit it',
        description="Simulate a full calibration campaign of a balance (the memo's "
        'cubic matrix as the truth, its Appendix A/B load schedule, noise '
        "like Table 17's cubic row), fit the linear, quadratic and cubic "
        "models and print Table 17 with the memo's numbers beside ours; "
        'optionally the fitted cubic matrix in the layout of Tables 12/16 '
        'and the campaign as a calibration bag.',
    )
    add_simulated_balance_arguments(parser, SimulatedBalance(seed=1), repeatable=True)
    parser.add_argument(
        '--bag', help='also write the campaign as a calibration bag (directory, must not exist)'
    )
    parser.add_argument(
        '--samples-per-point',
        type=int,
        default=1,
        help='bridge samples averaged per load point (default 1: one noisy reading per point)',
    )
    parser.add_argument(
        '--no-diagnosis',
        action='store_true',
        help='do not examine the residuals for effects the base model lacks',
    )
    parser.add_argument(
        '--matrix', action='store_true', help='print the fitted cubic matrix (memo layout)'
    )
    parser.add_argument(
        '--schedule',
        metavar='FILE',
        help='run the campaign on this load schedule (layout of the Appendix A/B '
        'sheets, e.g. from balance-calib design) instead of the balance '
        "config's; needs one --balance",
    )
    parser.set_defaults(func=run)


def run(args) -> int:
    from ..accuracy.sigma import format_sigma_table
    from ..accuracy.tables import format_coefficient_tables
    from ..calibrate.path import calibrate
    from ..calibration_settings import CalibrationSettings
    from ..config import ConfigError, load_balance_config
    from ..gates.limits import acceptance_limits
    from ..refit.bag_points import campaign_points, load_points_record, reduced_points
    from ..refit.errors import RefitError
    from ..refit.pipeline import CalibrationResult, summary_line
    from ..schedule_file import schedule_for
    from ..simulation.balance_sim import simulate_campaign, SimulationSettings, table17_noise
    from ..simulation.effects import parse_effects
    from .errors import CommandError

    if args.seed < 0:
        raise CommandError(
            f'--seed {args.seed}: the seed of the noise generator must be 0 or more'
        )
    if args.samples_per_point < 1:
        raise CommandError(
            f'--samples-per-point {args.samples_per_point}: at least 1 sample per load point'
        )
    try:
        effects = parse_effects(args.effects)
    except ValueError as err:
        raise CommandError(str(err)) from None
    if args.schedule and len(args.balance or []) != 1:
        raise CommandError('--schedule runs on one balance: give exactly one --balance')
    names = args.balance or ['lmc6522', 'b660h']
    configs = []
    for name in names:
        try:
            config = load_balance_config(name)
            if args.schedule:  # the campaign's schedule is the one the gates judge it against
                margin = acceptance_limits(config).capacity_margin  # the capacity gate's
                config = replace(config, schedule=schedule_for(config, args.schedule, margin))
            configs.append(config)
        except ConfigError as err:
            raise CommandError(str(err)) from None
    bags = (
        {config.name: _bag_path(args.bag, config, len(names)) for config in configs}
        if args.bag
        else {}
    )
    for path in bags.values():  # before the work: a campaign is not simulated for nothing
        _check_new_bag(path)
    for config in configs:
        # the samples taken while weights change are simulated whether or not a bag is written:
        # the noise is drawn in time order, so leaving them out for the fit alone would give the
        # points other noise, and the bag another campaign than the one fitted (the fit uses the
        # points only)
        settings = SimulationSettings(
            samples_per_point=args.samples_per_point,
            seed=args.seed,
            noise_sigma_pct_fs=table17_noise(config),
            transition_samples=TRANSITION_SAMPLES,
        )
        try:
            campaign = simulate_campaign(config, settings=settings, effects=effects)
        except ArithmeticError as err:  # Newton's inverse: a load the truth model cannot give
            raise CommandError(f'{args.schedule or config.name}: {err}') from None
        print(
            f'\n=== {config.name}: simulated campaign of {len(campaign.point)} points '
            f'{"on " + str(args.schedule) + " " if args.schedule else ""}(truth: memo cubic '
            'matrix; noise: Table 17 cubic row; effects: '
            f'{", ".join(campaign.effects) or "none"})'
        )
        try:
            points = reduced_points(load_points_record(campaign_points(campaign)), config)
            result = cast(
                CalibrationResult,
                calibrate(points, CalibrationSettings(diagnose=not args.no_diagnosis)),
            )
        except RefitError as err:
            raise CommandError(str(err)) from None
        rows = {}
        for order in ('linear', 'quadratic', 'cubic'):
            rows[f'TM-663 Table 17 {order}'] = config.table17_sigma_pct_fs.get(order, {})
            rows[f'balance_calib    {order}'] = result.fits[order].sigma_pct_fs
        print('σ in % FS, eqs. (44)-(49):')
        print(format_sigma_table(rows, config.components))
        print(summary_line(result.report))
        if args.matrix:
            print(
                '\nFitted cubic matrix (cf. TM-663 Table '
                f'{12 if config.name == "LMC6522" else 16}):'
            )
            print(format_coefficient_tables(result.fits['cubic'].fit.model))
        if args.bag:
            from ..bags.errors import BagError
            from ..simulation.campaign_bag import write_campaign_bag

            try:
                write_campaign_bag(campaign, bags[config.name])
            except (BagError, OSError) as err:
                raise CommandError(_one_line(str(err))) from None
            print(f'campaign bag: {bags[config.name]}', file=sys.stderr)
    return 0


def _bag_path(bag: str, config, balances: int) -> Path:
    """--bag itself for one balance, else one bag per balance inside it."""
    return Path(bag) if balances == 1 else Path(bag) / config.name.lower()


def _check_new_bag(path: Path) -> None:
    from .errors import CommandError

    if path.exists() or path.is_symlink():
        raise CommandError(
            f'--bag {path}: exists already; give a new directory (a bag is never overwritten)'
        )
    parent = next((p for p in path.absolute().parents if p.exists()), Path('/'))
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise CommandError(
            f'--bag {path}: cannot create it ({parent} is not a writable directory)'
        )


def _one_line(text: str) -> str:
    return ' '.join(text.split())
