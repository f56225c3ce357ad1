"""Where `refit`, `fit` and `export-table` write: an --out directory or file, never clobbered.

interfaces.md, "Command line": a DIR that already holds a calibration record (`calibration.yaml`
or `report.json`) is refused unless `--overwrite` is given (the same for `export-table`'s output
file); with `--overwrite` DIR ends up holding this run's files only.

How "this run's files only" is reached without deleting what is not ours: a run writes
everything into a staging directory first (nothing half-written). A new or empty DIR is the
staging directory renamed (one atomic rename). Into an existing DIR with `--overwrite`, the
earlier run's outputs that this run does not write again (a stale `effect_temperature.png`) are
removed, then each file is replaced by a rename, `calibration.yaml` last, so a reader always finds
a calibration and the report beside it is never older than it. Only names this tool writes
(`OWN_NAMES`, `OWN_PATTERNS`) are ever removed: a DIR holding anything else (notes, a bag, a
balance config) is refused with `--overwrite` rather than emptied, and the directory of the shipped
balance configs is refused always.
"""

from __future__ import annotations

import fnmatch
import os
from pathlib import Path
import shutil
import tempfile

from .config import CONFIG_DIR

CALIBRATION_RECORD = ('calibration.yaml', 'report.json')
# every file refit or fit writes into its --out, and what their staging may leave behind
OWN_NAMES = frozenset({'calibration.yaml', 'report.json', 'report.md', 'point_uncertainty.csv'})
OWN_PATTERNS = ('*.png', '.refit-staging-*', '.fit-staging-*', '.*.tmp')
FILE_MODE = 0o644
DIRECTORY_MODE = 0o755


class OutputError(ValueError):
    """The output cannot be written there; one line naming the path and what to do."""


def is_own_output(name: str) -> bool:
    """True for a file name refit or fit writes (or their staging leaves) in an --out directory."""
    return name in OWN_NAMES or any(fnmatch.fnmatchcase(name, p) for p in OWN_PATTERNS)


def _shipped_config_names() -> frozenset[str]:
    try:
        return frozenset(p.name for p in CONFIG_DIR.glob('*.yaml'))
    except OSError:
        return frozenset()


def _refuse_config_dir(directory: Path, what: str) -> None:
    """The shipped balance configs are inputs: nothing is written beside them."""
    resolved = directory.resolve()
    config_dir = CONFIG_DIR.resolve()
    shipped = sorted(_shipped_config_names() & _names_in(resolved))
    if resolved == config_dir or config_dir in resolved.parents or shipped:
        beside = shipped[0] if shipped else 'the shipped balance configs'
        raise OutputError(
            f'{directory}: {what} is the directory of the balance configs (it holds '
            f'{beside}); choose another directory'
        )


def _names_in(directory: Path) -> set[str]:
    try:
        return {p.name for p in directory.iterdir()} if directory.is_dir() else set()
    except OSError:
        return set()


def _writable(directory: Path) -> bool:
    try:  # os.access says yes to root everywhere: try it
        with tempfile.TemporaryFile(dir=directory, prefix='.out-probe-'):
            return True
    except OSError:
        return False


def check_out_dir(out_dir: str | Path, *, overwrite: bool) -> Path:
    """Refuse, before any work, an --out directory this run must not write.

    Parameters
    ----------
    out_dir : the --out directory (it may not exist yet).
    overwrite : the command's --overwrite: replace an earlier calibration record in it.

    Returns
    -------
    Where to stage the outputs: DIR's parent (a new DIR then appears whole with one rename), or
    DIR itself when only DIR is writable.

    Raises
    ------
    OutputError
        not a directory, not writable, the balance configs' directory, a calibration record there
        without `overwrite`, or with `overwrite` files there that are not this tool's outputs.
    """
    out_dir = Path(out_dir).absolute()
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputError(f'{out_dir}: --out exists and is not a directory')
    base = next((p for p in [out_dir, *out_dir.parents] if p.exists()), Path('/'))
    if not base.is_dir():
        raise OutputError(
            f'{out_dir}: cannot create the output directory ({base} is not a directory)'
        )
    if not _writable(base):
        raise OutputError(f'{out_dir}: output directory not writable ({base} is not writable)')
    _refuse_config_dir(out_dir, '--out')
    names = _names_in(out_dir)
    record = [n for n in CALIBRATION_RECORD if n in names]
    if record and not overwrite:
        raise OutputError(
            f'{out_dir}: --out holds the calibration record of an earlier run '
            f'({", ".join(record)}); give --overwrite to replace it, or another '
            f'--out'
        )
    if record and overwrite:
        foreign = sorted(n for n in names if not is_own_output(n))
        if foreign:
            more = f' and {len(foreign) - 1} more' if len(foreign) > 1 else ''
            raise OutputError(
                f'{out_dir}: --overwrite replaces only the files of an earlier run, '
                f'and --out also holds {foreign[0]}{more}; move them away or choose '
                f'another --out'
            )
    if out_dir.exists() and not _writable(out_dir.parent):
        return out_dir
    return out_dir.parent


def check_out_file(path: str | Path, *, overwrite: bool) -> Path:
    """Refuse, before any work, an output file (export-table --out) this run must not write.

    Raises OutputError for a directory, an existing file without `overwrite`, an unwritable
    directory, or a file among the shipped balance configs. Returns the path.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputError(f'{path}: --out is a directory; give the file to write')
    parent = path.absolute().parent
    if not parent.is_dir():
        raise OutputError(f'{path}: its directory {parent} does not exist')
    _refuse_config_dir(parent, 'the directory of --out')
    if path.exists() and not overwrite:
        raise OutputError(
            f'{path}: --out exists already; give --overwrite to replace it, or another --out'
        )
    if not _writable(parent):
        raise OutputError(f'{path}: {parent} is not writable')
    return path


def make_staging(out_dir: str | Path, stage_in: Path, tool: str) -> Path:
    """A fresh staging directory for `tool` ('refit', 'fit') in `stage_in` (check_out_dir's
    result).

    It is named after this process, so that a later run removes it if this one is killed.
    """
    out_dir = Path(out_dir)
    prefix = f'.{tool}-staging-{out_dir.name}-'
    stage_in.mkdir(parents=True, exist_ok=True)
    for stale in stage_in.glob(f'{prefix}*'):
        try:
            pid = int(stale.name[len(prefix) :].split('-', 1)[0])
        except ValueError:
            continue
        if pid != os.getpid() and not _alive(pid):
            shutil.rmtree(stale, ignore_errors=True)
    return Path(tempfile.mkdtemp(prefix=f'{prefix}{os.getpid()}-', dir=stage_in))


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def install_outputs(staging: Path, out_dir: str | Path, *, overwrite: bool) -> Path:
    """Move the complete staging directory's files into out_dir; remove staging.

    With `overwrite`, when out_dir holds an earlier run's record and nothing but this tool's
    outputs (check_out_dir refused anything else), the outputs this run did not write again are
    removed first; otherwise nothing is removed. Files end 0644, a new DIR 0755.
    """
    out_dir = Path(out_dir)
    try:
        for item in staging.iterdir():
            os.chmod(item, FILE_MODE)
        os.chmod(staging, DIRECTORY_MODE)
        try:
            os.rename(staging, out_dir)  # a new or empty out_dir: one atomic rename
            return out_dir
        except OSError:
            pass
        out_dir.mkdir(parents=True, exist_ok=True)
        new = {p.name for p in staging.iterdir()}
        present = _names_in(out_dir)
        earlier_run = any(n in present for n in CALIBRATION_RECORD)
        if overwrite and earlier_run and all(is_own_output(n) for n in present):
            # an earlier run's directory (a record, nothing but outputs): its files not written
            # again go; a *.png beside a user's files without a record is not ours to judge
            for old in out_dir.iterdir():
                if old.name not in new and not old.is_dir():  # staging: make_staging's care
                    old.unlink()
        # calibration.yaml last: whoever watches it sees the report of the same run
        for item in sorted(staging.iterdir(), key=lambda p: p.name == 'calibration.yaml'):
            item.replace(out_dir / item.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out_dir
