"""--serial and --operator: the signed record's (record.py) options of refit, fit and check."""

from __future__ import annotations


def add_record_arguments(parser, serial_default: str = "the balance config's `serial`") -> None:
    parser.add_argument(
        '--serial',
        default=None,
        help=f'serial number of the balance for the signed record (default {serial_default})',
    )
    parser.add_argument(
        '--operator',
        default=None,
        help='who performed it, for the signed record (report.json record.operator; default null)',
    )
