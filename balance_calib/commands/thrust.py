"""`balance-calib nozzle` and `balance-calib line-fit`: the thrust-stand lab manual's two hand
calculations (ideal nozzle, eqs. (1)-(15); calibration line, eqs. (25)-(27)) as JSON.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
import sys

from .errors import CommandError

LINE_FIT_MIN_POINTS = 3


def register(subparsers) -> None:
    nozzle = subparsers.add_parser(
        'nozzle',
        help='ideal nozzle performance (thrust-stand manual eqs. 1-15) as JSON',
        description=(
            'Ideal isentropic nozzle at chamber pressure PC and ambient PA (both absolute, Pa; '
            'p_c = p_G + p_a). flow_regime says whether the isentropic theory holds: with a '
            'normal shock inside the nozzle (PA above shock_at_exit_ambient_pa, the ambient at '
            'which a normal shock stands at the exit) or a throat that is not choked, the '
            'numbers it gets wrong (thrust_n, cf, isp_s, the exit state) are null and `warning` '
            '(also on stderr) says why; the exit status stays 0.'
        ),
    )
    nozzle.add_argument(
        '--throat-mm', type=float, default=2.5, help='throat diameter D_t, mm (2.5)'
    )
    nozzle.add_argument('--exit-mm', type=float, default=3.3, help='exit diameter D_e, mm (3.3)')
    nozzle.add_argument(
        '--chamber-pa', type=float, required=True, help='absolute chamber pressure p_c, Pa'
    )
    nozzle.add_argument(
        '--ambient-pa', type=float, default=101325.0, help='ambient pressure p_a, Pa (101325)'
    )
    nozzle.add_argument(
        '--gamma', type=float, default=1.402, help='ratio of specific heats (1.402)'
    )
    nozzle.add_argument(
        '--gas-constant', type=float, default=287.1, help='gas constant R, J/(kg K) (287.1)'
    )
    nozzle.add_argument(
        '--chamber-k', type=float, default=293.15, help='chamber temperature T_c, K (293.15)'
    )
    nozzle.add_argument(
        '--subsonic',
        action='store_true',
        help="take eq. (4)'s subsonic root for p_e/p_c instead of the supersonic one",
    )
    nozzle.set_defaults(func=run_nozzle)

    line = subparsers.add_parser(
        'line-fit',
        help='least-squares line y = a x + b with σ_a (manual eqs. 25-27) as JSON',
        description=(
            'Fit y = a x + b to a CSV with columns x,y and optional sx,sy (per-point σ) and '
            'direction (+1 loading, -1 unloading; default: from the order of y). Without sx, sy '
            'the σ come from the scatter about the line. The residual is then examined for '
            'hysteresis, nonlinearity and zero drift (adopted when the data support them, '
            'cross-validated) and for structure none of them explains (unexplained); '
            'sigma_pct_fs before/after, FS = the largest |y|.'
        ),
    )
    line.add_argument(
        'csv_file',
        metavar='FILE.csv',
        help='points in the order they were taken: columns x,y; optional sx,sy and direction',
    )
    line.set_defaults(func=run_line_fit)


def _finite_positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise CommandError(f'{name} must be a positive number, got {value}')


def run_nozzle(args) -> int:
    from balance_calib.thrust_stand.nozzle import (
        critical_pressure_ratio,
        Nozzle,
        shock_free_ambient_ratio,
    )

    for name in ('throat_mm', 'exit_mm', 'chamber_pa', 'gas_constant', 'chamber_k'):
        _finite_positive('--' + name.replace('_', '-'), getattr(args, name))
    if not (math.isfinite(args.ambient_pa) and args.ambient_pa >= 0):
        raise CommandError(f'--ambient-pa must be >= 0, got {args.ambient_pa}')
    if not (math.isfinite(args.gamma) and args.gamma > 1):
        raise CommandError(f'--gamma must be > 1, got {args.gamma}')
    if args.exit_mm < args.throat_mm:
        raise CommandError(
            f'--exit-mm {args.exit_mm} is smaller than --throat-mm {args.throat_mm}: '
            'not a converging-diverging nozzle'
        )
    if args.chamber_pa <= args.ambient_pa:
        raise CommandError(
            f'--chamber-pa {args.chamber_pa:g} does not exceed --ambient-pa {args.ambient_pa:g}: '
            'no flow (the chamber pressure is absolute, p_G + p_a)'
        )
    nozzle = Nozzle(args.throat_mm * 1e-3, args.exit_mm * 1e-3, args.gamma, args.gas_constant)
    performance = nozzle.performance(
        args.chamber_pa,
        args.ambient_pa,
        args.chamber_k,
        'subsonic' if args.subsonic else 'supersonic',
    )
    shock_at_exit_pa = args.chamber_pa * shock_free_ambient_ratio(nozzle.area_ratio, args.gamma)
    result = {
        **performance.as_dict(),
        'throat_area_m2': nozzle.throat_area_m2,
        'exit_area_m2': nozzle.exit_area_m2,
        'critical_pressure_ratio': critical_pressure_ratio(args.gamma),
        'gamma': args.gamma,
        'gas_constant_j_kg_k': args.gas_constant,
        'shock_at_exit_ambient_pa': shock_at_exit_pa,
        'warning': None,
    }
    warning = _not_isentropic(performance, shock_at_exit_pa)
    if warning:
        # the isentropic formulas do not hold: their numbers would be silently wrong
        for key in NOT_ISENTROPIC_KEYS[performance.flow_regime]:
            result[key] = None
        result['warning'] = warning
        print(f'balance-calib nozzle: warning: {warning}', file=sys.stderr)
    json.dump(result, sys.stdout, indent=2, ensure_ascii=False)  # ± and σ as they are
    sys.stdout.write('\n')
    return 0


# What the isentropic theory gets wrong in each regime where it does not hold: with a normal
# shock inside the diverging section the exit flow is subsonic (exit state, thrust, C_F, I_sp);
# below choking the throat is subsonic too (the mass flow of eq. (2) as well).
_EXIT_AND_THRUST = ('exit_pa', 'exit_mach', 'exit_velocity_m_s', 'thrust_n', 'cf', 'isp_s')
NOT_ISENTROPIC_KEYS = {
    'shock in nozzle': _EXIT_AND_THRUST,
    'not choked': ('mass_flow_kg_s',) + _EXIT_AND_THRUST,
}


def _not_isentropic(performance, shock_at_exit_pa: float) -> str:
    """The one-line reason the isentropic thrust does not hold, '' when it does."""
    if performance.flow_regime == 'shock in nozzle':
        return (
            f'a normal shock stands inside the nozzle: ambient {performance.ambient_pa:.6g} Pa is '
            f'above {shock_at_exit_pa:.6g} Pa, where the shock reaches the exit (manual eq. (4) '
            f'supersonic root, A_e/A_t = {performance.area_ratio:.4g}); the isentropic thrust, '
            'C_F and I_sp (eqs. (5), (12), (15)) do not hold and are null'
        )
    if performance.flow_regime == 'not choked':
        ratio = performance.ambient_pa / performance.chamber_pa
        return (
            f"the throat is not choked: p_a/p_c = {ratio:.4g} is above eq. (4)'s subsonic root; "
            'eqs. (2), (5), (12) do not hold and are null'
        )
    return ''


def _read_points(path: Path) -> dict[str, list[float]]:
    if not path.is_file():
        raise CommandError(f'{path}: no such file')
    try:
        with path.open(newline='') as stream:
            reader = csv.DictReader(stream)
            header = [name.strip() for name in (reader.fieldnames or [])]
            missing = [name for name in ('x', 'y') if name not in header]
            if missing:
                raise CommandError(
                    f'{path}: missing column(s) {", ".join(missing)} '
                    f'(header is {",".join(header) or "empty"}; need x,y and optionally sx,sy)'
                )
            reader.fieldnames = header
            wanted = [name for name in ('x', 'y', 'sx', 'sy', 'direction') if name in header]
            columns: dict[str, list[float]] = {name: [] for name in wanted}
            for row in reader:
                if all((value or '').strip() == '' for value in row.values()):
                    continue  # blank line
                for name in wanted:
                    text = (row.get(name) or '').strip()
                    try:
                        value = float(text)
                    except ValueError:
                        raise CommandError(
                            f'{path}: line {reader.line_num}: column {name} is {text!r}, '
                            'not a number'
                        ) from None
                    if (
                        not math.isfinite(value)
                        or (name in ('sx', 'sy') and value < 0)
                        or (name == 'direction' and value not in (-1.0, 1.0))
                    ):
                        raise CommandError(
                            f'{path}: line {reader.line_num}: column {name} = {text} '
                            'is not allowed'
                            + (' (+1 loading, -1 unloading)' if name == 'direction' else '')
                        )
                    columns[name].append(value)
    except (OSError, UnicodeDecodeError, csv.Error) as error:
        raise CommandError(f'{path}: cannot read: {error}') from None
    return columns


def run_line_fit(args) -> int:
    from balance_calib.thrust_stand.line_fit import fit_line
    from balance_calib.thrust_stand.one_axis import examine_line
    from balance_calib.thrust_stand.significant import format_value_error

    path = Path(args.csv_file)
    columns = _read_points(path)
    n = len(columns['x'])
    if n < LINE_FIT_MIN_POINTS:
        raise CommandError(
            f'{path}: {n} point(s); a line with an uncertainty needs at least '
            f'{LINE_FIT_MIN_POINTS}'
        )
    try:
        fit = fit_line(columns['x'], columns['y'], columns.get('sx'), columns.get('sy'))
        examined = examine_line(
            columns['x'],
            columns['y'],
            columns.get('direction'),
            columns.get('sx'),
            columns.get('sy'),
        )
    except ValueError as error:
        raise CommandError(f'{path}: {error}') from None

    def formatted(name, value, error):
        try:
            return format_value_error(value, error, name=name)
        except ValueError:  # an exact fit has no error to round to
            return f'{name} = {value:.10g} ± 0'

    result = {
        'a': fit.slope,
        'b': fit.intercept,
        'sigma_a': fit.sigma_slope,
        'sigma_b': fit.sigma_intercept,
        'n': fit.n,
        'residual_std': fit.residual_std,
        'sigma_source': fit.sigma_source,
        'sums': {
            'x': fit.sums.sum_x,
            'y': fit.sums.sum_y,
            'xy': fit.sums.sum_xy,
            'xx': fit.sums.sum_xx,
        },
        'formatted': formatted('a', fit.slope, fit.sigma_slope),
        'formatted_b': formatted('b', fit.intercept, fit.sigma_intercept),
        # the residual examined (interfaces.md, "One-axis calibration with its residual examined")
        **examined.to_report(),
    }
    json.dump(result, sys.stdout, indent=2, ensure_ascii=False)  # ± and σ as they are
    sys.stdout.write('\n')
    return 0
