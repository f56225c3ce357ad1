"""`balance-calib`: the command line. Each sub-command lives in its own module with
`register(subparsers)`; this file only lists them. Exit 0 on success; on bad input one line on
stderr naming what is wrong and a non-zero status.
"""
from __future__ import annotations

import argparse
import importlib
import sys

# module path -> provides register(subparsers) that adds one or more sub-commands
COMMAND_MODULES = (
    'balance_calib.commands.simulate',
    'balance_calib.commands.refit',
    'balance_calib.commands.thrust',
)


class CommandError(Exception):
    """Bad input: printed as one line on stderr, exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='balance-calib', description=__doc__.split('\n')[0])
    subparsers = parser.add_subparsers(dest='command', required=True)
    for module_name in COMMAND_MODULES:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as err:
            if err.name == module_name:
                continue  # not written yet
            raise
        module.register(subparsers)
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


if __name__ == '__main__':
    sys.exit(main())
