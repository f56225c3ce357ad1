"""~/refit's pipeline in its own process, out of the streaming process's way.

A refit is seconds of numpy, plotting and bag reading; in the node's interpreter it stalls the
stream (p99 latency 0.4 ms -> 200-300 ms measured). Here the same `run_refit` runs in a process
started with multiprocessing's spawn method (a fresh interpreter: no forked rclpy state), at a lower
CPU priority; progress lines and the result (the calibration as a plain dict) come back over a pipe.
A failure of any kind -- the pipeline's RefitError, a crash, a kill, a timeout -- is a RefitFailed
with one line saying why; the caller keeps its calibration.
"""
from __future__ import annotations

import multiprocessing
import os
import signal
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..calibration_file import Calibration, calibration_from_dict


class RefitFailed(Exception):
    """The refit did not produce a calibration; str() is the one-line reason."""


@dataclass(frozen=True)
class RefitProduct:
    calibration: Calibration
    summary: str
    calibration_path: Path | None


def _child(connection, bags, balance, out_dir, model) -> None:
    try:
        os.nice(10)          # the stream's process comes first on a shared machine
    except OSError:
        pass
    try:
        from balance_calib.refit.pipeline import run_refit
        result = run_refit(list(bags), balance, out_dir, model=model, diagnose=True,
                           progress=lambda line: connection.send(('progress', str(line))))
        path = getattr(result, 'calibration_path', None)
        connection.send(('ok', result.calibration.to_dict(), str(getattr(result, 'summary', '') or 'done'),
                         None if path is None else str(path)))
    except ValueError as err:          # RefitError, BagError, ConfigError: the message names the file
        connection.send(('error', ' '.join(str(err).split('\n')[:1]) or type(err).__name__))
    except BaseException as err:       # a bug rather than bad input: say what kind
        connection.send(('error', f'{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ""}'))
    finally:
        connection.close()


def run_refit_in_process(bags, balance: str, out_dir: Path, model: str, *, progress: Callable[[str], None],
                         timeout_s: float, started: Callable[[int], None] | None = None) -> RefitProduct:
    """Run the refit pipeline in a spawned process; blocks the calling (worker) thread until it ends."""
    context = multiprocessing.get_context('spawn')
    receiver, sender = context.Pipe(duplex=False)
    process = context.Process(target=_child, args=(sender, [str(b) for b in bags], balance, str(out_dir), model),
                              name='balance_calib refit', daemon=True)
    process.start()
    sender.close()
    if started is not None:
        started(process.pid)
    deadline = time.monotonic() + timeout_s
    outcome = None
    try:
        while outcome is None:
            if receiver.poll(0.1):
                try:
                    message = receiver.recv()
                except EOFError:
                    break                  # the child is gone without a result
                if message[0] == 'progress':
                    progress(message[1])
                else:
                    outcome = message
            elif time.monotonic() > deadline:
                raise RefitFailed(f'the refit took longer than refit_timeout_s = {timeout_s:g} s and was stopped')
    finally:
        if outcome is None and process.is_alive():
            process.kill()
        process.join(5.0)
        receiver.close()
    if outcome is None:
        code = process.exitcode
        how = f'was killed by signal {signal.Signals(-code).name}' if code is not None and code < 0 else \
            f'exited with status {code}'
        raise RefitFailed(f'the refit process {how} before it finished')
    if outcome[0] == 'error':
        raise RefitFailed(outcome[1])
    _, calibration, summary, path = outcome
    try:
        return RefitProduct(calibration_from_dict(calibration, f'refit result in {out_dir}'), summary,
                            None if path is None else Path(path))
    except ValueError as err:
        raise RefitFailed(str(err)) from None
