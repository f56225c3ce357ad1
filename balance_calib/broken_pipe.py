"""What a command does when whoever read its output has gone (`... | head`): stop quietly.

Python raises BrokenPipeError at the next write, and again when it flushes stdout at exit; the
second one prints a traceback. Pointing stdout at /dev/null lets the process end without it.
"""

from __future__ import annotations

import os
import sys


def stdout_closed() -> None:
    """Send what is left of stdout to /dev/null, so that the interpreter's exit flush succeeds."""
    os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
