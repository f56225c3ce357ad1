"""`balance-calib`: the command line. Each sub-command lives in its own module with
`register(subparsers)`; this file only lists them. Exit 0 on success; on bad input one line on
stderr naming what is wrong and a non-zero status.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from .commands.errors import CommandError

# module path -> provides register(subparsers) that adds one or more sub-commands
COMMAND_MODULES = (
    'balance_calib.commands.simulate',
    'balance_calib.commands.refit',
    'balance_calib.commands.thrust',
    'balance_calib.commands.fit',
    'balance_calib.commands.reduce',
    'balance_calib.commands.coverage',
    'balance_calib.commands.design',
    'balance_calib.commands.check',
    'balance_calib.commands.compare',
    'balance_calib.commands.virtual_daq',
)


DESCRIPTION = (
    'Calibrate six-component wind-tunnel strain-gauge balances after NAL TM-663 '
    '(linear, quadratic and cubic models, calibration-body tare, zero points, σ in % of full '
    'scale) and the one-axis thrust stand. Loads are N and N·m, bridge outputs mV.'
)
EPILOG = (
    'Run "balance-calib COMMAND --help" for the options of one command. Exit status 0 on success; '
    'on bad input one line on stderr saying what is wrong with which file, and status 2. '
    'The ROS 2 nodes (bridge_publisher, balance_calibrator, balance_recorder, thrust_analyzer) '
    'are separate executables; see launchless_scripts/ and the README.'
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='balance-calib', description=DESCRIPTION, epilog=EPILOG)
    subparsers = parser.add_subparsers(
        dest='command', required=True, metavar='COMMAND', title='commands'
    )
    for module_name in COMMAND_MODULES:
        importlib.import_module(module_name).register(subparsers)  # an import error must show
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except CommandError as err:
        print(f'balance-calib {args.command}: {err}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f'balance-calib {args.command}: interrupted', file=sys.stderr)
        return 130
    except BrokenPipeError:  # `balance-calib ... | head`: the reader is gone
        from .broken_pipe import stdout_closed

        stdout_closed()
        return 0


if __name__ == '__main__':
    # `python -m balance_calib.cli`: run the imported module's main, whose CommandError is the one
    # the sub-commands raise (this file runs as __main__, a second copy of the class)
    from balance_calib.cli import main as _main

    sys.exit(_main())
