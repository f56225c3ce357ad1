"""The record a laboratory signs (interfaces.md, "A record a laboratory signs"): who, what, when,
with which software and from which files, and the expanded uncertainty U = k·u of a reading at the
rated load. One builder for `refit`, `fit` and `check`; report.md opens with
`identification_markdown` and closes with `signature_markdown`.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
import subprocess
from typing import Any, Mapping, Sequence

import numpy as np

EXPANSION_K = 2.0  # GUM coverage factor of the expanded uncertainty
_GIT_TIMEOUT_S = 5.0
_CHUNK_BYTES = 1 << 20


def file_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of a file's bytes, read in chunks."""
    digest = hashlib.sha256()
    with open(path, 'rb') as stream:
        for chunk in iter(lambda: stream.read(_CHUNK_BYTES), b''):
            digest.update(chunk)
    return digest.hexdigest()


def input_files(paths: Sequence[str | Path]) -> list[dict[str, str | None]]:
    """[{"file", "sha256"}] of each input; a directory (a rosbag2 bag) by each file in it, in
    name order. A file that cannot be read gets sha256 null (the record still names it).
    """
    entries: list[dict[str, str | None]] = []
    for given in paths:
        path = Path(given)
        files = sorted(p for p in path.rglob('*') if p.is_file()) if path.is_dir() else [path]
        for file in files:
            try:
                digest: str | None = file_sha256(file)
            except OSError:
                digest = None
            entries.append({'file': str(file), 'sha256': digest})
    return entries


def software() -> dict[str, str | None]:
    """Name, version and the git commit of the package's checkout (null when the package does not
    run from a checkout, e.g. installed as a wheel, or git is missing: never an error).
    """
    from . import __version__

    return {'name': 'balance_calib', 'version': __version__, 'commit': _checkout_commit()}


def _checkout_commit() -> str | None:
    package = Path(__file__).resolve().parent
    try:
        top = _git(package, 'rev-parse', '--show-toplevel')
        # an installed copy inside a checkout (a venv under the work tree) is not that checkout
        if top is None or (Path(top) / package.name / '__init__.py').resolve() != (
            package / '__init__.py'
        ):
            return None
        commit = _git(package, 'rev-parse', 'HEAD')
    except (OSError, ValueError, subprocess.SubprocessError):
        return None
    return commit if commit and len(commit) >= 40 else None


def _git(directory: Path, *arguments: str) -> str | None:
    done = subprocess.run(
        ['git', '-C', str(directory), *arguments],
        capture_output=True,
        text=True,
        timeout=_GIT_TIMEOUT_S,
        check=False,
    )
    return done.stdout.strip() if done.returncode == 0 else None


def expanded_uncertainty_pct_fs(calibration, model: str = 'adopted', k: float = EXPANSION_K):
    """{"k": k, "FX": U, …}: U = k·u (% FS) of a reading of each component at its rated load
    (the others zero), u as /balance/wrench_uncertainty gives it (model/uncertainty.py); null
    for a component whose u cannot be computed (no coefficient covariance, no inverse).
    """
    from .coverage.run import run_coverage
    from .model.inverse import InverseDidNotConverge
    from .model.uncertainty import UncertaintyUnavailable

    components = list(calibration.components)
    values: list[float | None] = [None] * len(components)
    try:
        rated = np.diag(np.asarray(calibration.capacity, dtype=float))
        coverage = run_coverage(calibration, rated, model=model)
        u = np.diag(coverage.uncertainty_pct_fs)
        values = [round(float(k * x), 5) if np.isfinite(x) else None for x in u]
    except (UncertaintyUnavailable, InverseDidNotConverge, ValueError, KeyError):
        pass
    result: dict[str, Any] = {'k': k if k != int(k) else int(k)}
    result.update(zip(components, values))
    return result


def signed_record(
    *,
    balance: str,
    serial: str | None,
    operator: str | None,
    inputs: Sequence[str | Path],
    calibration=None,
    model: str = 'adopted',
    date: str | None = None,
) -> dict[str, Any]:
    """The record's keys (interfaces.md): balance, serial, date (ISO 8601, UTC), operator,
    software, inputs (file + sha256), expanded_uncertainty_pct_fs (of `calibration`'s `model`;
    all null without a calibration).
    """
    from .calibration_file import now_iso

    return {
        'balance': balance,
        'serial': serial or None,
        'date': date or now_iso(),
        'operator': operator or None,
        'software': software(),
        'inputs': input_files(inputs),
        'expanded_uncertainty_pct_fs': (
            expanded_uncertainty_pct_fs(calibration, model)
            if calibration is not None
            else {'k': int(EXPANSION_K)}
        ),
    }


def identification_markdown(record: Mapping[str, Any]) -> list[str]:
    """The identification block report.md opens with."""
    program = record.get('software') or {}
    expanded = dict(record.get('expanded_uncertainty_pct_fs') or {})
    k = expanded.pop('k', EXPANSION_K)
    u_text = ', '.join(
        f'{c} {"n/a" if v is None else format(v, ".4f")}' for c, v in expanded.items()
    )
    inputs = record.get('inputs') or []
    lines = [
        '| | |',
        '|---|---|',
        f'| balance | {record.get("balance") or "—"} |',
        f'| serial number | {record.get("serial") or "not given"} |',
        f'| date | {record.get("date") or "—"} |',
        f'| operator | {record.get("operator") or "not given"} |',
        f'| software | {program.get("name", "balance_calib")} {program.get("version", "")}'
        f' (commit {program.get("commit") or "unknown: not run from a git checkout"}) |',
        f'| expanded uncertainty U (k = {k:g}) at the rated load, % FS | {u_text or "n/a"} |',
        f'| inputs | {len(inputs)} file(s), SHA-256 below |',
        '',
    ]
    lines += [f'- `{e["file"]}`: `{e.get("sha256") or "unreadable"}`' for e in inputs[:50]]
    if len(inputs) > 50:
        lines.append(f'- … and {len(inputs) - 50} more in report.json')
    return lines + ['']


def signature_markdown(what: str = 'calibration') -> list[str]:
    """The lines report.md closes with: who performed and who approved."""
    return [
        '',
        '## Signatures',
        '',
        f'Performed by: ______________________  date: __________  ({what})',
        '',
        'Approved by:  ______________________  date: __________',
        '',
    ]
