"""The thrust analyzer's comparison report: `<stem>.json` for programs, `<stem>.md` for people."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
import tempfile

from .analysis import ThrustComparison
from .significant import format_value_error


def report_paths(report_path: str | Path) -> tuple[Path, Path]:
    """'out/firing.json', 'out/firing.md' or 'out/firing' -> (out/firing.json, out/firing.md)."""
    path = Path(report_path)
    stem = path.with_suffix('') if path.suffix in ('.json', '.md') else path
    return stem.with_name(stem.name + '.json'), stem.with_name(stem.name + '.md')


def _pm(value: float, error: float, unit: str = '') -> str:
    try:
        return format_value_error(value, error, unit)
    except ValueError:
        return f'{value:.6g} {unit}'.strip()


def report_markdown(comparison: ThrustComparison) -> str:
    c = comparison
    theory = c.theory
    theory_thrust = f'{theory.thrust_n:.4g}' if theory else '—'
    theory_cf = f'{theory.cf:.4f}' if theory else '—'
    lines = [
        '# Thrust stand: measured and theoretical thrust coefficient',
        '',
        f'Nozzle D_t = {c.nozzle.throat_diameter_m * 1e3:.4g} mm, D_e = '
        f'{c.nozzle.exit_diameter_m * 1e3:.4g} mm (A_e/A_t = {c.nozzle.area_ratio:.4f}), γ = '
        f'{c.nozzle.gamma}, R = {c.nozzle.gas_constant_j_kg_k} J/(kg·K).',
        '',
        '| quantity | measured | theory (isentropic) |',
        '|---|---|---|',
        f'| thrust F_t [N] | {_pm(c.thrust_n.mean, c.thrust_n.sigma)} | {theory_thrust} |',
        f'| C_F | {_pm(c.cf_measured.value, c.cf_measured.sigma)} | {theory_cf} |',
        f'| p_c = p_G + p_a [Pa] | {c.chamber_pa:.6g} | |',
        f'| p_a [Pa] | {_pm(c.ambient_pa.mean, c.ambient_pa.sigma)} | |',
    ]
    if theory:
        lines += [
            f'| p_e/p_c (eq. 4) | | {theory.pe_over_pc:.5f} |',
            f'| p_e [Pa] | | {theory.exit_pa:.6g} ({theory.expansion}, {theory.flow_regime}) |',
            '',
            f'Measured / theoretical C_F = {c.cf_ratio:.3f}.',
        ]
    else:
        lines += ['', 'No flow (p_c <= p_a): no theoretical value.']
    lines += [
        '',
        '## Uncertainty of the measured C_F (lab manual §A1.4)',
        '',
        '| input | contribution, abs(∂C_F/∂x_i) Δx_i |',
        '|---|---|',
        *[f'| {name} | {value:.3g} |' for name, value in c.cf_measured.contributions.items()],
        f'| root-sum-square, eq. (20) | {c.cf_measured.sigma:.3g} |',
        f'| worst case, eq. (19) | {c.cf_measured.worst_case:.3g} |',
        f'| dominant, eq. (21) | {c.cf_measured.dominant:.3g} ({c.cf_measured.dominant_input}) |',
        '',
    ]
    return '\n'.join(lines)


def _atomic_write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f'.{path.name}.')
    try:
        with os.fdopen(handle, 'w') as stream:
            stream.write(text)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def _json_safe(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


def write_report(
    report_path: str | Path, comparison: ThrustComparison, extra: dict | None = None
) -> tuple[Path, Path]:
    """Write both files (each atomically); returns their paths."""
    json_path, markdown_path = report_paths(report_path)
    data = _json_safe({**comparison.as_dict(), **(extra or {})})
    _atomic_write(json_path, json.dumps(data, indent=2) + '\n')
    _atomic_write(markdown_path, report_markdown(comparison))
    return json_path, markdown_path
