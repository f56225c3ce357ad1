"""`COMMAND | head`: a reader that leaves early ends the command quietly, never with a
traceback.
"""

import os
import subprocess

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _stderr_when_reader_leaves(argv: list[str]) -> tuple[int, str]:
    """Run argv with stdout into a pipe whose reader closes after the first line."""
    process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    process.stdout.readline()
    process.stdout.close()  # the reader is gone, as `| head -1` leaves
    _, stderr = process.communicate(timeout=120)
    return process.returncode, stderr.decode(errors='replace')


@pytest.mark.parametrize(
    'argv',
    [
        ['bridge_publisher', '--help'],  # a node's long parameter help
        ['balance-calib', 'simulate', '--balance', 'lmc6522', '--no-diagnosis', '--matrix'],
    ],
)
def test_a_reader_that_leaves_early_gets_no_traceback(argv):
    status, stderr = _stderr_when_reader_leaves(argv)
    assert 'Traceback' not in stderr and 'BrokenPipeError' not in stderr, stderr
    assert status == 0, (status, stderr)
