"""The calibration record on disk: calibration.yaml, report.json, report.md and the figures.

One writer for every calibration (bags, simulations, tables). Everything but the figures is
written into a staging directory beside `out_dir` and moved in only when complete
(output_dir.py: a new out_dir appears whole with one rename; into an existing one, allowed with
overwrite, the earlier run's outputs not written again are removed and each file is replaced by a
rename, calibration.yaml last), so a failure or a kill leaves `out_dir` as it was. Files are
readable by others (0644, directory 0755).

The figures come last, off the critical path: report.md already names every figure; once the
record is installed `written` is called, then each figure is drawn into a staging directory and
renamed into out_dir. A figure that cannot be drawn is said (progress, report's `warnings`) and
taken out of report.json and report.md (both rewritten atomically); the calibration stays.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import json
import os
from pathlib import Path
import shutil
from typing import Any, Callable, Mapping, Sequence, TYPE_CHECKING

from ..calibration_settings import Progress, RecordOptions

if TYPE_CHECKING:
    from ..model.calibration import Calibration

Figure = tuple[str, Callable[[Path], Any]]  # (file name, draw(path))


@dataclass(frozen=True)
class Record:
    """What a calibration writes: made by the bag or the table side (refit/, tables/)."""

    calibration: Calibration
    report: dict
    markdown: Callable[[dict], str]  # report.md of the report
    # the figures in report.md's order, their names known before any is drawn
    figure_plan: Callable[[], Sequence[Figure]] = tuple
    files: Mapping[str, str] = field(default_factory=dict)  # other files: name -> text
    tool: str = 'refit'  # names the staging directory (output_dir.make_staging)
    result: Any = None  # the calibration result the record was made from


def report_json(report: Mapping) -> str:
    """report.json's text: indented, no NaN."""
    return json.dumps(report, indent=2, allow_nan=False) + '\n'


def write_record(record: Record, options: RecordOptions, progress: Progress | None = None) -> Path:
    """Write the record into options.out_dir; returns the directory written."""
    from ..calibration_file import save_calibration
    from ..output_dir import check_out_dir, install_outputs, make_staging

    out_dir = Path(options.out_dir)
    figures = list(record.figure_plan()) if options.plots else []
    record.report.setdefault('plots', [name for name, _ in figures])
    staging = make_staging(
        out_dir, check_out_dir(out_dir, overwrite=options.overwrite), record.tool
    )
    try:
        save_calibration(staging / 'calibration.yaml', record.calibration)
        for name, text in record.files.items():
            (staging / name).write_text(text)
        (staging / 'report.json').write_text(report_json(record.report))
        (staging / 'report.md').write_text(record.markdown(record.report))
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    out = install_outputs(staging, out_dir, overwrite=options.overwrite)
    if options.written is not None:
        options.written(record.result, out)
    if figures:
        draw_record_figures(record, figures, out, progress or (lambda message: None))
    return out


def draw_record_figures(
    record: Record, figures: Sequence[Figure], out_dir: Path, say: Progress
) -> None:
    """Draw (name, draw) into a staging directory in out_dir and rename each into place; a
    failure is told and taken out of the report (report.json, report.md rewritten atomically).
    """
    from ..calibration_file import write_text_atomically
    from ..figure_png import draw_figures
    from ..output_dir import FILE_MODE, make_staging

    staging = make_staging(out_dir, out_dir, record.tool)
    try:
        # the residual figures share one figure (refit/plots.py); the others are drawn beside
        failed = draw_figures(
            figures, staging, beside=lambda name: not name.startswith('residuals_')
        )
        for name in dict.fromkeys(name for name, _ in figures):  # a name drawn twice: once
            if name not in failed:
                os.chmod(staging / name, FILE_MODE)
                os.replace(staging / name, out_dir / name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    if not failed:
        return
    report = record.report
    report['plots'] = [name for name in report.get('plots', []) if name not in failed]
    report['warnings'] = list(report.get('warnings', [])) + [
        f'figure {name} could not be drawn ({why}); the calibration is not affected'
        for name, why in failed.items()
    ]
    for line in report['warnings'][-len(failed) :]:
        say(line)
    write_text_atomically(out_dir / 'report.json', report_json(report))
    write_text_atomically(out_dir / 'report.md', record.markdown(report))
