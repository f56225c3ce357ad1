"""What `reduce` writes: coefficients.csv (interfaces.md, exactly), report.md, one figure per
coefficient against α with the compared calibration models overlaid (TM-663 Figs. 12-13).
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path
import tempfile

import numpy as np

from ..calibration_file import write_text_atomically
from .bag_io import TRUTH_WIND_TOPIC
from .pipeline import Reduction

COEFFICIENTS = ('CAF', 'CY', 'CN', 'Cl', 'Cm', 'Cn', 'CD', 'CL')
NICE = {
    'CAF': 'C_AF',
    'CY': 'C_Y',
    'CN': 'C_N',
    'Cl': 'C_l',
    'Cm': 'C_m',
    'Cn': 'C_n',
    'CD': 'C_D',
    'CL': 'C_L',
}
MEANING = {
    'CAF': 'axial force (body)',
    'CY': 'side force (body)',
    'CN': 'normal force (body)',
    'Cl': 'rolling moment about the MRC',
    'Cm': 'pitching moment about the MRC',
    'Cn': 'yawing moment about the MRC',
    'CD': 'drag (wind axes)',
    'CL': 'lift (wind axes)',
}
DPI = 100


def point_values(point) -> np.ndarray:
    """(8,) CAF, CY, CN, Cl, Cm, Cn, CD, CL of a reduced held point (NaN when it could not be
    reduced).
    """
    if point.reduced is None:
        return np.full(8, np.nan)
    return np.concatenate([point.reduced.body, point.reduced.wind[[0, 2]]])


def point_uncertainties(point) -> np.ndarray:
    return np.concatenate([point.uncertainty_body, point.uncertainty_wind[[0, 2]]])


def table(reduction: Reduction):
    """Rows (one per held wind-on attitude of the main model): dict of column -> value; and the
    per-model arrays (model -> (R, 8)) aligned with the rows, plus uncertainties of the main model.
    """
    main_points = reduction.main.result.wind_on
    holds = [p.hold for p in main_points]
    values = {reduction.main.name: np.array([point_values(p) for p in main_points])}
    for run in reduction.compared:
        by_hold = {p.hold: p for p in run.result.wind_on}
        values[run.name] = np.array(
            [point_values(by_hold[h]) if h in by_hold else np.full(8, np.nan) for h in holds]
        )
    uncertainty = np.array([point_uncertainties(p) for p in main_points])
    return main_points, values, uncertainty


def coefficients_csv(reduction: Reduction) -> str:
    points, values, _ = table(reduction)
    header = ['alpha_deg', 'beta_deg', 'q_pa'] + list(COEFFICIENTS)
    for run in reduction.compared:
        header += [f'{c}_{run.name}' for c in COEFFICIENTS]
    out = io.StringIO()
    writer = csv.writer(out, lineterminator='\n')
    writer.writerow(header)
    for i, point in enumerate(points):
        if point.reduced is None:
            alpha, beta = (
                np.degrees(point.support_attitude[1]),
                np.degrees(point.support_attitude[2]),
            )
        else:
            alpha, beta = float(point.reduced.alpha_deg), float(point.reduced.beta_deg)
        row = [alpha, beta, point.q_pa] + list(values[reduction.main.name][i])
        for run in reduction.compared:
            row += list(values[run.name][i])
        writer.writerow([repr(float(v)) for v in row])
    return out.getvalue()


def truth_by_point(reduction: Reduction) -> np.ndarray | None:
    """(R, 8) the simulation's true coefficients at each main point (mean over its samples), if
    recorded.
    """
    samples = reduction.samples
    if samples.truth_body is None:
        return None
    points = reduction.main.result.wind_on
    rows = []
    for p in points:
        body = samples.truth_body[p.first_sample : p.first_sample + p.samples].mean(axis=0)
        wind = (
            samples.truth_wind[p.first_sample : p.first_sample + p.samples].mean(axis=0)
            if samples.truth_wind is not None
            else np.full(6, np.nan)
        )
        rows.append(np.concatenate([body, wind[[0, 2]]]))
    return np.array(rows)


NO_TRUTH = 'no truth'


def _largest_error(error: np.ndarray, ratio: np.ndarray) -> str:
    """'largest error (largest ratio u)' over the finite entries of (R,) arrays; NO_TRUTH if
    there are none.
    """
    error, ratio = error[np.isfinite(error)], ratio[np.isfinite(ratio)]
    if not error.size:
        return NO_TRUTH
    if not ratio.size:
        return f'{error.max():.2e} (u unknown)'
    return f'{error.max():.2e} ({ratio.max():.1f} u)'


def _fmt(value: float, digits: int = 5) -> str:
    return 'NaN' if not np.isfinite(value) else f'{value:.{digits}f}'


def electrical_zero_text(reduction: Reduction) -> str:
    """The zero subtracted in output space and where it came from, or 'none'."""
    from ..units import BRIDGE_OUTPUTS

    zero = reduction.electrical_zero_mv
    if zero is None:
        return "none (no --electrical-zero-mv, no calibrator's ~/zero in the bags)"
    values = ', '.join(f'{b} {v:+.5f}' for b, v in zip(BRIDGE_OUTPUTS, zero))
    return f'{values} mV ({reduction.electrical_zero_source})'


def report_markdown(reduction: Reduction, figures: list[str]) -> str:
    model, cal, samples = reduction.model, reduction.calibration, reduction.samples
    points, values, uncertainty = table(reduction)
    lines = [f'# Wind-on data reduction: {model.name} on {cal.balance}', '']
    lines += [
        '## Model',
        '',
        f'- file: `{model.path}`',
        f'- S = {model.reference_area_m2:g} m², c = {model.reference_chord_m:g} m, b = '
        f'{model.reference_span_m:g} m',
        f'- moment reference centre (body axes from the balance centre, x forward): '
        f'{np.array2string(model.moment_reference_centre_m, precision=4)} m',
        f'- deflection: Δα = {model.deflection.alpha_rad_per_n:g} rad/N · F_Z + '
        f'{model.deflection.alpha_rad_per_nm:g} rad/(N·m) · M_Y; Δβ = '
        f'{model.deflection.beta_rad_per_n:g} rad/N · F_Y + '
        f'{model.deflection.beta_rad_per_nm:g} rad/(N·m) · M_Z',
        '',
    ]
    lines += [
        '## Calibration and conditions',
        '',
        f'- calibration: `{reduction.calibration_path}` ({cal.balance}); reduced through '
        f'**{reduction.main.name}**'
        + (
            f', compared with {", ".join(r.name for r in reduction.compared)}'
            if reduction.compared
            else ''
        ),
        f'- installation: {reduction.installation.name} (TM-663 §10.2; tunnel = '
        f'{reduction.installation.spec})',
        f'- load σ of a point used for the tare weights and the uncertainty: '
        f'{np.array2string(reduction.sigma_loads, precision=3)} N, N·m ({reduction.sigma_source})',
        '- electrical zero subtracted from the bridge outputs (output space): '
        + electrical_zero_text(reduction),
        f'- bags: {", ".join(str(s) for s in samples.sources)}',
        f'- samples: {len(samples.q_pa)} matched, {samples.stale} left out (attitude or q∞ '
        'missing or older than allowed)',
        f'- holds: {reduction.main.result.holds} found, {len(points)} wind-on points, '
        f'{sum(p.wind_off for p in reduction.main.result.points)} wind-off points; q∞ '
        f'{min(p.q_pa for p in points):.0f} … {max(p.q_pa for p in points):.0f} Pa',
        '',
    ]
    lines += ['## Weight tare (load space)', '']
    for run in reduction.runs:
        for k, tare in enumerate(run.result.tares):
            cg_sigma = tare.cg_sigma_m * 1000
            lines.append(
                f'- {run.name}, sweep {k + 1} ({tare.points} wind-off points, {tare.source}): W '
                f'= {tare.weight_n:.3f} ± {tare.weight_sigma_n:.3f} N, CG = '
                f'({", ".join(f"{1000 * c:.2f} ± {s:.2f}" for c, s in zip(tare.cg_m, cg_sigma))}) '
                f'mm, offsets {np.array2string(tare.offsets, precision=3)} N, N·m'
            )
    lines += ['', '## Zero drift during the run', ''] + zero_drift_section(reduction)
    warnings = [w for run in reduction.runs for w in run.result.warnings]
    lines += ['', '## Warnings', ''] + ([f'- {w}' for w in warnings] or ['- none']) + ['']
    main = values[reduction.main.name]
    lines += [
        f'## Coefficients per α ({reduction.main.name}; ± standard uncertainty, k = 1, from the '
        'calibration σ and the tare)',
        '',
        '| α (°) | β (°) | q∞ (Pa) | n | ' + ' | '.join(NICE[c] for c in COEFFICIENTS) + ' |',
        '|' + '---:|' * (4 + len(COEFFICIENTS)),
    ]
    for i, p in enumerate(points):
        alpha = p.reduced.alpha_deg if p.reduced is not None else np.degrees(p.support_attitude[1])
        beta = p.reduced.beta_deg if p.reduced is not None else np.degrees(p.support_attitude[2])
        cells = [
            f'{_fmt(main[i, k])} ± {_fmt(uncertainty[i, k])}' for k in range(len(COEFFICIENTS))
        ]
        lines.append(
            f'| {float(alpha):.3f} | {float(beta):.3f} | {p.q_pa:.0f} | {p.samples} | '
            + ' | '.join(cells)
            + ' |'
        )
    if reduction.compared:
        lines += [
            '',
            f'## Compared models: difference from {reduction.main.name} per α',
            '',
            '| model | α (°) | ' + ' | '.join(f'Δ{NICE[c]}' for c in COEFFICIENTS) + ' |',
            '|---|' + '---:|' * (1 + len(COEFFICIENTS)),
        ]
        for run in reduction.compared:
            for i, p in enumerate(points):
                alpha = (
                    p.reduced.alpha_deg
                    if p.reduced is not None
                    else np.degrees(p.support_attitude[1])
                )
                diff = values[run.name][i] - main[i]
                lines.append(
                    f'| {run.name} | {float(alpha):.3f} | '
                    + ' | '.join(_fmt(d) for d in diff)
                    + ' |'
                )
    truth = truth_by_point(reduction)
    if truth is not None:
        lines += [
            '',
            "## Against the simulation's truth (/aero/truth)",
            '',
            "Largest |reduced − true| over the α sweep, and in units of the point's uncertainty "
            "u:",
            '',
            '| model | ' + ' | '.join(NICE[c] for c in COEFFICIENTS) + ' |',
            '|---|' + '---:|' * len(COEFFICIENTS),
        ]
        absent = []
        for run in reduction.runs:
            error = np.abs(values[run.name] - truth)
            with np.errstate(divide='ignore', invalid='ignore'):
                ratio = error / uncertainty
            cells = [_largest_error(error[:, k], ratio[:, k]) for k in range(len(COEFFICIENTS))]
            absent += [
                NICE[c]
                for c, cell in zip(COEFFICIENTS, cells)
                if cell == NO_TRUTH and NICE[c] not in absent
            ]
            lines.append(f'| {run.name} | ' + ' | '.join(cells) + ' |')
        if absent:
            wind_only = samples.truth_wind is None and set(absent) <= {NICE['CD'], NICE['CL']}
            why = (
                f'the bag has no {TRUTH_WIND_TOPIC}'
                if wind_only
                else 'the truth or the reduced value is missing at every point'
            )
            lines += [
                '',
                f'{NO_TRUTH}: no point with both a reduced value and the truth for '
                f'{", ".join(absent)} ({why})',
            ]
    lines += ['', '## Coverage of this run by the calibration', ''] + coverage_section(reduction)
    lines += ['', '## Figures', ''] + [f'- [{f}]({f})' for f in figures] + ['']
    lines += [
        'Axes and signs: interfaces.md "Wind-tunnel data reduction"; body coefficients about '
        'the moment reference centre, C_D and C_L in wind axes; α and β are the '
        'deflection-corrected angles.',
        '',
    ]
    return '\n'.join(lines)


def zero_drift_lines(run, components) -> list[str]:
    """How one model's run handled the zero's drift, and the shift when it was measured."""
    from .zero_drift import WARN_BEYOND_SIGMA

    drift = run.zero_drift
    if drift.shift is None:
        return [f'- {run.name}: the drift of the zero was not corrected: {drift.reason}.']
    how = (
        'the wind-off offsets interpolated linearly in time between them'
        if drift.corrected
        else 'not corrected (--zero-drift none): the pre-run offsets throughout'
    )
    lines = [
        f'- {run.name}: pre-run sweep at t = {drift.pre_s:.2f} s, post-run sweep at t = '
        f'{drift.post_s:.2f} s; {how}.'
    ]
    if run.zero_shift_pct_fs is not None:
        lines.append(
            '  shift (post − pre), % FS: '
            + ', '.join(f'{c} {v:+.4f}' for c, v in zip(components, run.zero_shift_pct_fs))
            + f' (warned beyond {WARN_BEYOND_SIGMA:g}σ)'
        )
    return lines


def zero_drift_section(reduction: Reduction) -> list[str]:
    """The shift of the zero between the bracketing wind-off sweeps (interfaces.md, `reduce`'s
    zero drift), per calibration component in % FS beside the calibration's σ.
    """
    from .pipeline import calibration_sigma_pct_fs

    components = reduction.calibration.components
    lines = [
        'The wind-off offsets (the zero, load space) of the sweeps before and after the wind-on '
        'part, at the same attitudes; the post-run offsets fitted with the pre-run weight and CG.',
        '',
    ]
    for run in reduction.runs:
        lines += zero_drift_lines(run, components)
    if any(run.zero_shift_pct_fs is not None for run in reduction.runs):
        sigma = calibration_sigma_pct_fs(reduction.calibration)
        lines.append(
            "- the calibration's σ, % FS: "
            + ', '.join(f'{c} {v:.4f}' for c, v in zip(components, sigma))
        )
    return lines


def coverage_section(reduction: Reduction) -> list[str]:
    """The `coverage` command's summary for every sample of the run (coverage/run.py)."""
    from ..coverage.run import summary_table

    coverage = reduction.coverage
    if coverage is None:
        return [
            f"Not available: the calibration's {reduction.main.name} model carries no "
            f"coefficient covariance (the memo's published matrices); refit it to have one."
        ]
    return [
        'Predicted standard uncertainty (k = 1) of the calibrated load at every sample, from '
        'the coefficient covariance (as `/balance/wrench_uncertainty`), balance axes, and the '
        "share of the samples outside the support of the calibration's schedule (`coverage` "
        'command, interfaces.md); figure [coverage.png](coverage.png).',
        '',
        '```',
        summary_table(coverage.summary(), coverage.components),
        '```',
    ]


def coefficient_figure(reduction: Reduction, coefficient: str, path: Path) -> Path:
    """Left: the coefficient against α for every model (Figs. 12-13 overlay); right: each model's
    difference from the truth when the bag has it, else from the main model.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    points, values, uncertainty = table(reduction)
    k = COEFFICIENTS.index(coefficient)
    alpha = np.array(
        [float(p.reduced.alpha_deg) if p.reduced is not None else np.nan for p in points]
    )
    truth = truth_by_point(reduction)
    reference = truth[:, k] if truth is not None else values[reduction.main.name][:, k]
    reference_name = 'truth' if truth is not None else reduction.main.name
    figure = Figure(figsize=(11.0, 4.4))
    left, right = figure.add_subplot(1, 2, 1), figure.add_subplot(1, 2, 2)
    markers = {
        'linear': ('s', 'tab:red'),
        'quadratic': ('^', 'tab:green'),
        'cubic': ('o', 'tab:blue'),
    }
    for index, (name, table_values) in enumerate(values.items()):
        marker, colour = markers.get(name, ('D', f'C{index + 3}'))
        left.plot(
            alpha, table_values[:, k], marker=marker, color=colour, mfc='none', lw=1.0, label=name
        )
        right.plot(
            alpha,
            table_values[:, k] - reference,
            marker=marker,
            color=colour,
            mfc='none',
            lw=1.0,
            label=name,
        )
    if truth is not None:
        left.plot(alpha, truth[:, k], color='black', lw=0.8, ls='--', label='truth (simulation)')
    u = uncertainty[:, k]
    right.fill_between(alpha, -u, u, color='0.85', label='± u (k = 1)')
    right.axhline(0.0, color='black', lw=0.6)
    left.set_xlabel('angle of attack α (°)')
    right.set_xlabel('angle of attack α (°)')
    left.set_ylabel(NICE[coefficient])
    right.set_ylabel(f'{NICE[coefficient]} − {NICE[coefficient]} ({reference_name})')
    left.set_title(f'{NICE[coefficient]}: {MEANING[coefficient]}')
    right.set_title(f'difference from the {reference_name}')
    for axes in (left, right):
        axes.grid(True, lw=0.4, color='0.85')
        axes.legend(fontsize=8)
    figure.suptitle(
        f'{reduction.model.name} on {reduction.calibration.balance}, q∞ ≈ '
        f'{np.mean([p.q_pa for p in points]) / 1000:.1f} kPa ({reduction.installation.name})'
    )
    figure.tight_layout()
    FigureCanvasAgg(figure)
    figure.savefig(path, dpi=DPI)
    return path


def write_outputs(reduction: Reduction, out_dir: Path) -> list[Path]:
    """Write everything into out_dir; figures first into a temporary directory, so that a failure
    leaves nothing half-written.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    names = [f'coefficient_{c}.png' for c in COEFFICIENTS]
    with tempfile.TemporaryDirectory(dir=out_dir, prefix='.reduce-') as tmp:
        for coefficient, name in zip(COEFFICIENTS, names):
            coefficient_figure(reduction, coefficient, Path(tmp) / name)
        if reduction.coverage is not None:
            from ..coverage.plots import coverage_figure

            names.append('coverage.png')
            coverage_figure(
                reduction.coverage,
                Path(tmp) / names[-1],
                (reduction.samples.stamps_ns - reduction.samples.stamps_ns[0]) / 1e9,
            )
        csv_text = coefficients_csv(reduction)
        report = report_markdown(reduction, names)
        for name in names:
            os.replace(Path(tmp) / name, out_dir / name)
    write_text_atomically(out_dir / 'coefficients.csv', csv_text)
    write_text_atomically(out_dir / 'report.md', report)
    return [out_dir / 'coefficients.csv', out_dir / 'report.md'] + [out_dir / n for n in names]
