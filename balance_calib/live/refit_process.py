"""~/refit's pipeline in its own process, out of the streaming process's way.

A refit is seconds of numpy, plotting and bag reading; in the node's interpreter it stalls the
stream (p99 latency 0.4 ms -> 200-300 ms measured). Here the same `run_refit` runs in a process
started with multiprocessing's spawn method (a fresh interpreter: no forked rclpy state), at a
lower CPU priority, killed by the kernel if the node dies (PR_SET_PDEATHSIG); progress lines and
the result (the calibration as a plain dict) come back over a pipe. The result is sent as soon as
calibration.yaml and the report are written: the process draws the figures after it, unwaited
for (reaped, or killed at the timeout, by a background thread). A failure of any kind -- the
pipeline's RefitError, a crash, a kill, a timeout -- is a RefitFailed with one line saying why; the
caller keeps its calibration.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import datetime as _dt
import multiprocessing
import os
from pathlib import Path
import re
import signal
import time
from typing import Callable

from ..calibration_file import calibration_from_dict, save_calibration, write_text_atomically
from ..model.active_calibration import activate
from ..model.calibration import Calibration
from ..tunnel_axes import Installation
from .parameters import check_regular_file


class RefitFailed(Exception):
    """The refit did not produce a calibration; str() is the one-line reason."""


@dataclass(frozen=True)
class RefitProduct:
    calibration: Calibration
    summary: str
    calibration_path: Path | None


def _die_with_parent() -> None:
    """Linux: SIGKILL this process when the node that started it dies (no orphan refit writing
    on).
    """
    try:
        import ctypes

        ctypes.CDLL('libc.so.6', use_errno=True).prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _child(connection, bags, balance, out_dir, model, parent_pid, active=None) -> None:
    _die_with_parent()
    if os.getppid() != parent_pid:  # the node died before prctl took effect
        return
    try:
        os.nice(10)  # the stream's process comes first on a shared machine
    except OSError:
        pass
    replied: list[bool] = []  # after the reply the caller reads no more from the pipe
    try:
        from balance_calib.calibrate.from_bags import RefitSettings as PipelineSettings
        from balance_calib.calibrate.from_bags import run_refit

        def reply(result) -> None:
            # calibration.yaml and the report are in place: the figures follow without the caller
            path = getattr(result, 'calibration_path', None)
            connection.send(
                (
                    'ok',
                    result.calibration.to_dict(),
                    str(getattr(result, 'summary', '') or 'done'),
                    None if path is None else str(path),
                )
            )
            replied.append(True)

        result = run_refit(
            list(bags),
            balance,
            out_dir,
            PipelineSettings(
                model=model,
                diagnose=True,
                active_calibration=active,
                progress=lambda line: replied or connection.send(('progress', str(line))),
                written=reply,
            ),
        )
        if not replied:
            reply(result)
    except ValueError as err:  # RefitError, BagError, ConfigError: the message names the file
        if not replied:
            connection.send(('error', ' '.join(str(err).split('\n')[:1]) or type(err).__name__))
    except BaseException as err:  # a bug rather than bad input: say what kind
        if not replied:
            connection.send(
                ('error', f'{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ""}')
            )
    finally:
        connection.close()


def run_refit_in_process(
    bags,
    balance: str,
    out_dir: Path,
    model: str,
    *,
    progress: Callable[[str], None],
    timeout_s: float,
    started: Callable[[int], None] | None = None,
    active_calibration: str | None = None,
) -> RefitProduct:
    """Run the refit pipeline in a spawned process; blocks the calling (worker) thread until it
    ends.

    active_calibration: the calibration file in use; the refit's acceptance gates refuse a new one
    whose sensitivities moved far from it (gates/sensitivity.py).
    """
    context = multiprocessing.get_context('spawn')
    receiver, sender = context.Pipe(duplex=False)
    process = context.Process(
        target=_child,
        args=(
            sender,
            [str(b) for b in bags],
            balance,
            str(out_dir),
            model,
            os.getpid(),
            active_calibration,
        ),
        name='balance_calib refit',
        daemon=True,
    )
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
                    break  # the child is gone without a result
                if message[0] == 'progress':
                    progress(message[1])
                else:
                    outcome = message
            elif time.monotonic() > deadline:
                raise RefitFailed(
                    f'the refit took longer than refit_timeout_s = {timeout_s:g} s and was stopped'
                )
    finally:
        if outcome is None and process.is_alive():
            process.kill()
            process.join(5.0)
        elif outcome is not None:
            # the reply comes before the figures: the process draws them on, within the timeout
            _finish_in_background(process, deadline)
        receiver.close()
    if outcome is None:
        code = process.exitcode
        how = (
            f'was killed by signal {signal.Signals(-code).name}'
            if code is not None and code < 0
            else f'exited with status {code}'
        )
        raise RefitFailed(f'the refit process {how} before it finished')
    if outcome[0] == 'error':
        raise RefitFailed(outcome[1])
    _, calibration, summary, path = outcome
    try:
        return RefitProduct(
            calibration_from_dict(calibration, f'refit result in {out_dir}'),
            summary,
            None if path is None else Path(path),
        )
    except ValueError as err:
        raise RefitFailed(str(err)) from None


def _finish_in_background(process, deadline: float) -> None:
    """Reap the refit process once it has drawn its figures; kill it at the deadline."""
    import threading

    def wait() -> None:
        process.join(max(0.0, deadline - time.monotonic()))
        if process.is_alive():
            process.kill()
            process.join(5.0)

    threading.Thread(target=wait, name='refit figures', daemon=True).start()


# --- ~/refit as a job: what the node fixes when it is called, and what comes back
# ------------------
@dataclass(frozen=True)
class RefitSettings:
    """What the node's parameters fix for ~/refit: the balance, the `model` parameter, how the
    result is put in force (installation, envelope margin, output range factor) and how long the
    refit may take.
    """

    balance: str
    model: str  # the node's `model` parameter
    installation: Installation
    envelope_margin: float
    output_range_factor: float
    timeout_s: float

    @property
    def base(self) -> str:
        """The polynomial model the refit fits: the `model` parameter, or cubic for others."""
        return self.model if self.model in ('linear', 'quadratic', 'cubic') else 'cubic'


@dataclass(frozen=True)
class RefitJob:
    bags: tuple[Path, ...]
    out_dir: Path
    calibration_file: Path  # replaced by the result (unless it is a balance config)
    settings: RefitSettings


_TOP_LEVEL_KEY = re.compile(r'^([A-Za-z_][\w-]*)\s*:', re.MULTILINE)


def is_balance_config(path) -> bool:
    """True for a balance description (config/*.yaml); a refit must not overwrite one of those.

    Decided from the top-level keys (`matrices` and no `models`), read as the unindented `key:`
    lines of the block-style YAML both kinds of file are: parsing a calibration.yaml whole takes
    ~80 ms of Python, which the node's worker thread would spend beside the live stream at every
    ~/refit.
    """
    try:
        check_regular_file(path, 'calibration_file')
        keys = set(_TOP_LEVEL_KEY.findall(Path(path).read_text()))
    except (OSError, ValueError, UnicodeDecodeError):
        return False
    return 'matrices' in keys and 'models' not in keys


def make_refit_job(bags, report_dir, calibration_file, settings: RefitSettings) -> RefitJob:
    """ValueError (or OSError) saying what is wrong with the parameters, before any work."""
    bags = tuple(Path(b).expanduser() for b in bags if b)
    if not bags:
        raise ValueError(
            'parameter calibration_bags is empty: set it first, e.g. '
            'launchless_scripts/ros param set /balance_calibrator calibration_bags "[BAG_DIR]"'
        )
    missing = [str(b) for b in bags if not b.exists()]
    if missing:
        raise ValueError(f'calibration bag {", ".join(missing)} does not exist')
    root = Path(report_dir).expanduser()
    root.mkdir(parents=True, exist_ok=True)
    out_dir = root / ('refit-' + _dt.datetime.now(_dt.timezone.utc).strftime('%Y%m%dT%H%M%SZ'))
    for k in range(1, 1000):
        if not out_dir.exists():
            break
        out_dir = out_dir.with_name(f'{out_dir.name.split("+")[0]}+{k}')
    return RefitJob(bags, out_dir, Path(calibration_file), settings)


def _install(target: Path, calibration: Calibration, written: Path | None) -> None:
    """Replace target atomically with `calibration`: a copy of the refit's own calibration.yaml
    (the same calibration, written by its process) when there is one, else written here. Dumping
    the YAML here would cost ~45 ms of Python in the node's worker thread beside the live stream.
    """
    if written is not None and Path(written).is_file():
        write_text_atomically(target, Path(written).read_text())
    else:
        save_calibration(target, calibration)


def run_refit_job(job: RefitJob, refit_function, progress: Callable[[str], None]):
    """(ActiveCalibration, calibration file, reply) on success, else the one-line reason (str).

    refit_function: run_refit's signature, called in this thread (tests inject one); None = the
    pipeline in its own process. The calibration file is replaced atomically only after the new
    calibration has been checked (activate); a balance config is never overwritten.
    """
    settings = job.settings
    try:
        if refit_function is not None:
            # imported here: the node's process runs the pipeline in another (run_refit_in_process)
            from ..calibrate.from_bags import RefitSettings as PipelineSettings

            result = refit_function(
                list(job.bags),
                settings.balance,
                job.out_dir,
                PipelineSettings(model=settings.base, diagnose=True, progress=progress),
            )
            calibration, summary = result.calibration, getattr(result, 'summary', '') or 'done'
            path = getattr(result, 'calibration_path', None)
        else:
            active_file = (
                None if is_balance_config(job.calibration_file) else str(job.calibration_file)
            )
            product = run_refit_in_process(
                job.bags,
                settings.balance,
                job.out_dir,
                settings.base,
                progress=progress,
                timeout_s=settings.timeout_s,
                active_calibration=active_file,
            )
            calibration, summary, path = (
                product.calibration,
                product.summary,
                product.calibration_path,
            )
        if not isinstance(calibration, Calibration):
            raise TypeError(f'the refit returned {type(calibration).__name__}, not a Calibration')
        active = activate(
            calibration,
            settings.model,
            settings.installation,
            settings.envelope_margin,
            output_range_factor=settings.output_range_factor,
        )
    # RefitError, BagError, ConfigError: the message names the file
    except (RefitFailed, ValueError) as err:
        return str(err)
    target = job.calibration_file
    try:
        if is_balance_config(target):
            # never overwrite a balance description: it carries the schedule the refit needs
            target = Path(path or job.out_dir / 'calibration.yaml')
            if not target.exists():
                save_calibration(target, calibration)
            note = (
                f'{job.calibration_file} is a balance config and stays as it is; '
                f'calibration_file is now {target}'
            )
        else:
            _install(target, calibration, path)  # atomic replace
            note = f'{target} replaced'
    except OSError as err:
        return f'cannot write {target}: {err}'
    message = (
        f'refit OK: {summary}; now {active.model_name} model; {note}; report in {job.out_dir}; '
        'zero and tare kept'
    )
    return replace(active, source=str(target)), target, message
