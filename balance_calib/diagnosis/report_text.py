"""report.md's section on what the residuals show, for a wind-tunnel engineer.

The effects adopted with their evidence, the repeatability the points allow beside σ, what is left
that no effect explains (nothing adopted for it), and the warnings in plain words. Works on
report.json's keys alone (interfaces.md), so an old report renders too.
"""

from __future__ import annotations

from typing import Mapping


def _row(values: Mapping[str, float], components) -> str:
    return ' | '.join(
        f'{values[c]:.3f}' if c in values and values[c] == values[c] else '–' for c in components
    )


def findings_markdown(report: Mapping) -> list[str]:
    """Markdown lines: effects, repeatability vs σ, unexplained leftovers, warnings."""
    components = list(report['sigma_pct_fs']['before'])
    lines = ['## Effects found in the residuals', '']
    if not report['effects']:
        lines.append(
            'None: the residuals of the base model show nothing it lacks (nothing adopted).'
        )
    for i, effect in enumerate(report['effects'], 1):
        sig = ', '.join(f'{k} {v:.3f}' for k, v in effect.get('sigma_after_pct_fs', {}).items())
        live = (
            ''
            if effect.get('applied_live', True)
            else ' (fitted at calibration only, not applied live)'
        )
        lines += [
            f'{i}. **{effect["name"]}** on {", ".join(effect["components"])}{live}: '
            f'{effect["evidence"]}',
            f'   terms: `{", ".join(effect.get("terms", []))}`; σ after: {sig} % FS',
        ]
    repeatability = report.get('repeatability_pct_fs') or {}
    if repeatability:
        lines += [
            '',
            '### σ against the repeatability of the points',
            '',
            'The repeatability is the scatter the points allow by themselves (their own '
            'samples, or consecutive zero points when the samples are not at hand): a σ well '
            'above it means something is left in the residuals.',
            '',
            '| % FS | ' + ' | '.join(components) + ' |',
            '|---' * (len(components) + 1) + '|',
            '| σ before (base model) | '
            + _row(report['sigma_pct_fs']['before'], components)
            + ' |',
            '| σ after (adopted) | ' + _row(report['sigma_pct_fs']['after'], components) + ' |',
            '| repeatability | ' + _row(repeatability, components) + ' |',
        ]
    lines += ['', '## Left over and not explained', '']
    unexplained = report.get('unexplained') or []
    if not unexplained:
        lines.append(
            'Nothing: after the adopted model the residuals are at the repeatability of the '
            'points.'
            if repeatability
            else 'Not tested: the repeatability of the points is unknown.'
        )
    for entry in unexplained:
        sig = ', '.join(f'{k} {v:.3f}' for k, v in entry.get('sigma_pct_fs', {}).items())
        lines.append(
            f'- **{", ".join(entry["components"])}** (σ {sig} % FS), follows *{entry["tracks"]}*: '
            f'{entry["evidence"]}. Nothing was adopted for it; look for its cause before trusting '
            'this component beyond the repeatability.'
        )
    warnings = report.get('warnings') or []
    if warnings:
        lines += ['', '## Warnings', ''] + [f'- {w}' for w in warnings]
    lines.append('')
    return lines
