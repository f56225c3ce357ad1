"""Option groups that balance-calib's commands and the stories (launchless_scripts/windon,
launchless_scripts/campaign, launchless.aero_story) share: one function per group, so that an
option is spelled, typed and explained once, and the values that travel together come back as one
value (SimulatedBalance, WindOnConditions).

    the simulated balance   --balance --seed --effects        simulate, campaign, windon
    the model and its axes  --model --installation            reduce, windon, aero_story
    the wind-on conditions  --q-pa --noise-pct-fs             windon, aero_story
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import math

DEFAULT_BALANCE = 'lmc6522'
DEFAULT_AERO_MODEL = 'euler_replica_lmc6522'


@dataclass(frozen=True)
class SimulatedBalance:
    """The balance a simulated run follows: its config, the effects it has that nobody declared
    (simulation/effects.py), the seed of its noise.
    """

    name: str = DEFAULT_BALANCE
    effects: str = ''
    seed: int = 1


@dataclass(frozen=True)
class WindOnConditions:
    """What a simulated wind-on run flies: the model file, its installation (TM-663 §10.2), q∞
    and the σ of a held point's mean load (% FS; < 0: Table 17's cubic row).
    """

    model: str = DEFAULT_AERO_MODEL
    installation: str = 'upright'
    q_pa: float = 50000.0
    noise_sigma_pct_fs: float = -1.0


def positive_number(text: str) -> float:
    """An argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not value > 0 or value == math.inf:
        raise argparse.ArgumentTypeError(f'{text!r} is not a positive number')
    return value


def add_simulated_balance_arguments(
    parser, defaults: SimulatedBalance = SimulatedBalance(), *, repeatable: bool = False
) -> None:
    """--balance, --seed, --effects. repeatable: --balance may be given several times (default:
    both balances of the memo; args.balance is then a list or None).
    """
    parser.add_argument(
        '--balance',
        action='append' if repeatable else 'store',
        default=None if repeatable else defaults.name,
        help='balance config the simulated balance follows: lmc6522, b660h or a config path '
        + ('(repeatable; default both)' if repeatable else f'(default {defaults.name})'),
    )
    parser.add_argument(
        '--seed',
        type=int,  # a negative one: the command's own one-line refusal
        default=defaults.seed,
        help=f'random seed of the simulated noise (default {defaults.seed}; the same seed gives '
        'the same numbers)',
    )
    parser.add_argument(
        '--effects',
        default=defaults.effects,
        help='effects the simulated balance has and the base model lacks (nobody declares '
        'them), e.g. "temperature:sensitivity_per_k=0.0045|0|0|0|0|0" (default none)',
    )


def simulated_balance(args: argparse.Namespace) -> SimulatedBalance:
    """The group's values parsed (a single --balance)."""
    return SimulatedBalance(args.balance, args.effects, args.seed)


def add_model_arguments(
    parser,
    *,
    model_default: str | None = DEFAULT_AERO_MODEL,
    model: bool = True,
    permutations: bool = False,
) -> None:
    """--model (required when model_default is None; left out when model is False) and
    --installation (permutations: also a signed permutation of the components, as
    balance_calibrator and reduce take it; the simulated publisher flies upright or inverted).
    """
    if model:
        parser.add_argument(
            '--model',
            required=model_default is None,
            default=model_default,
            help='model file, config/models/NAME.yaml or its name'
            + (f' (default {model_default})' if model_default else ''),
        )
    parser.add_argument(
        '--installation',
        default='upright',
        help='upright (TM-663 §10.2.1) or inverted (§10.2.2)'
        + (', or a signed permutation like -FX,FY,-FZ,MX,MY,MZ' if permutations else '')
        + ' (default upright)',
    )


def add_wind_on_conditions_arguments(parser, defaults: WindOnConditions) -> None:
    """--q-pa and --noise-pct-fs."""
    parser.add_argument(
        '--q-pa',
        type=positive_number,
        default=defaults.q_pa,
        help=f'dynamic pressure of the wind-on holds, Pa (default {defaults.q_pa:g})',
    )
    noise = defaults.noise_sigma_pct_fs
    parser.add_argument(
        '--noise-pct-fs',
        type=float,
        default=noise,
        help="σ of a held point's mean load, %% FS (default "
        + (f"{noise:g}; -1: Table 17's cubic row)" if noise >= 0 else "-1: Table 17's cubic row)"),
    )


def wind_on_conditions(args: argparse.Namespace, model: str | None = None) -> WindOnConditions:
    """The groups' values parsed (model: when the parser has no --model)."""
    return WindOnConditions(
        model if model is not None else args.model,
        args.installation,
        args.q_pa,
        args.noise_pct_fs,
    )
