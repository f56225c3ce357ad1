"""check.md and compare.md, and the lines the commands print (interfaces.md, "Check loads, and
comparing two calibrations"; the record of record.py opens check.md and its signatures close it).
"""

from __future__ import annotations

from typing import Mapping

from ..record import identification_markdown, signature_markdown


def _f(value, digits: int = 4) -> str:
    """A signed number (an error, a difference), n/a for null."""
    return 'n/a' if value is None else f'{value:+.{digits}f}'


def _u(value, digits: int = 4) -> str:
    """An unsigned number (an RMS, an uncertainty), n/a for null."""
    return 'n/a' if value is None else f'{value:.{digits}f}'


def failed_lines(summary: Mapping) -> list[str]:
    """One line per failed component (its failed points and the worst of them), the warnings,
    then the verdict: what `check` prints. Every failed point is in check.json and check.md.
    """
    lines = []
    for component, entry in summary['components'].items():
        failed = [f for f in summary['failed'] if f['component'] == component]
        if not failed:
            continue
        worst = max(failed, key=lambda f: -1.0 if f['ratio'] is None else f['ratio'])
        outside = sum(bool(f.get('outside_support')) for f in failed)
        lines.append(
            f'FAILED {component}: {len(failed)} of {summary["points"]} check points beyond '
            f'k·u; worst {worst["point"]}: error {_f(worst["error_pct_fs"])} % FS, limit '
            f'{_u(worst["limit_pct_fs"])} % FS'
            + (f' ({outside} outside the calibrated range)' if outside else '')
        )
    lines += [f'warning: {w}' for w in summary.get('warnings', [])]
    failed = len(summary['failed'])
    worst_ratio = summary['worst_ratio']
    lines.append(
        f'verdict: {summary["verdict"]} ({summary["points"]} check points, {failed} of '
        f'{summary["point_components"]} point-components beyond k·u, k = {summary["k"]}; worst '
        f'|error|/(k·u) {"n/a" if worst_ratio is None else format(worst_ratio, ".2f")})'
    )
    return lines


def check_markdown(summary: Mapping, record: Mapping) -> str:
    components = list(summary['components'])
    lines = [f'# Check loads: {record.get("balance") or ""}', '']
    lines += identification_markdown(record)
    lines += [
        f'**Verdict: {summary["verdict"].upper()}** — {summary["points"]} check points from '
        f'`{summary["source"]}` read through model {summary["model"]}; a point-component passes '
        f'when |error| ≤ k·u, k = {summary["k"]}, u the standard uncertainty of the reading '
        "(as /balance/wrench_uncertainty: σ √(1 + leverage), the tare's share) combined with the "
        "standard error of the point's own mean. pass: every one passes; marginal: at most 5 % "
        'fail, each within 1.5·k·u; fail: otherwise.',
        '',
        '| component | RMS error, % FS | worst error, % FS | failed |',
        '|---|---|---|---|',
    ]
    for c in components:
        entry = summary['components'][c]
        lines.append(
            f'| {c} | {_u(entry["rms_error_pct_fs"])} | {_f(entry["worst_error_pct_fs"])} | '
            f'{entry["failed"]} |'
        )
    lines += ['']
    if summary['failed']:
        lines += [
            '## Failed point-components',
            '',
            '| point | component | error, % FS | limit k·u, % FS | outside the calibrated range |',
            '|---|---|---|---|---|',
        ]
        lines += [
            f'| {f["point"]} | {f["component"]} | {_f(f["error_pct_fs"])} | '
            f'{_u(f["limit_pct_fs"])} | '
            f'{"yes" if f.get("outside_support") else "no"} |'
            for f in summary['failed']
        ]
        lines.append('')
    outside = summary.get('outside_support') or []
    lines += ['## Calibrated range', '']
    if outside:
        lines += [
            f'Judged against {summary["support"]}. **{len(outside)} check points lie outside '
            'it: their readings are extrapolations**, whatever their pass/fail:',
            '',
        ] + [f'- {o["point"]}: {", ".join(o["components"])}' for o in outside[:40]]
        if len(outside) > 40:
            lines.append(f'- … and {len(outside) - 40} more in check.json')
    else:
        lines.append(f'Every check point lies inside {summary["support"]}.')
    lines += ['']
    if summary.get('warnings'):
        lines += ['## Warnings', ''] + [f'- {w}' for w in summary['warnings']] + ['']
    lines += ['![error against limit](check.png)', '']
    lines += signature_markdown('check loads')
    return '\n'.join(lines) + '\n'


def compare_lines(summary: Mapping) -> list[str]:
    """One line per changed component, then the verdict (what `compare` prints)."""
    lines = []
    for c in summary['changed']:
        entry = summary['components'][c]
        lines.append(
            f'CHANGED {c}: RMS difference {entry["rms_difference_pct_fs"]:.4f} % FS > '
            f'2 x combined u {entry["combined_u_pct_fs"]:.4f} % FS (worst '
            f'{_f(entry["worst_difference_pct_fs"])} % FS)'
        )
    lines += [f'warning: {w}' for w in summary.get('warnings', [])]
    moved = {
        v: s
        for v, s in summary['sensitivity_change_pct'].items()
        if s is not None and abs(s) >= 0.05
    }
    if moved:
        lines.append(
            'primary sensitivities moved: '
            + ', '.join(f'{v} {s:+.3f} %' for v, s in moved.items())
        )
    verdict = 'changed: ' + ', '.join(summary['changed']) if summary['changed'] else 'unchanged'
    lines.append(f'verdict: {verdict} ({summary["points"]} points: {summary["points_from"]})')
    return lines


def compare_markdown(summary: Mapping, name_a: str, name_b: str) -> str:
    changed = summary['changed']
    headline = 'Changed: ' + ', '.join(changed) if changed else 'Nothing changed.'
    lines = [
        '# Did the balance change? Two calibrations compared',
        '',
        f'A: `{name_a}` (model {summary["models"]["A"]}), B: `{name_b}` (model '
        f'{summary["models"]["B"]}); both read the outputs A reads as {summary["points"]} loads '
        f'({summary["points_from"]}). Difference B − A against the combined standard '
        'uncertainty √(u_A² + u_B²); a component has changed when its RMS difference exceeds '
        'twice the RMS combined uncertainty.',
        '',
        f'**{headline}**',
        '',
        '| component | RMS difference, % FS | worst difference, % FS | combined u (RMS), % FS '
        '| changed |',
        '|---|---|---|---|---|',
    ]
    for c, entry in summary['components'].items():
        lines.append(
            f'| {c} | {_u(entry["rms_difference_pct_fs"])} | '
            f'{_f(entry["worst_difference_pct_fs"])} | {_u(entry["combined_u_pct_fs"])} | '
            f'{"**yes**" if entry["changed"] else "no"} |'
        )
    lines += [
        '',
        '## Primary sensitivities (output per unit of own load at zero load), B/A − 1',
        '',
        '| bridge | change, % |',
        '|---|---|',
    ]
    lines += [f'| {v} | {_f(s, 3)} |' for v, s in summary['sensitivity_change_pct'].items()]
    lines += ['']
    if summary.get('warnings'):
        lines += ['## Warnings', ''] + [f'- {w}' for w in summary['warnings']] + ['']
    lines += ['![difference against uncertainty](compare.png)', '']
    return '\n'.join(lines) + '\n'
