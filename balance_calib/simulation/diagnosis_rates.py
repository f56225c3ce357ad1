"""Detection and false-discovery rates of the residual diagnosis on simulated campaigns.

    launchless_scripts/diagnosis_rates [--clean-seeds 50] [--seeds 10] [--sizes 1] [--jobs 2]
                                       [--families ...] [--outside ...] [--zero-points-only]

Every campaign is the Appendix A/B schedule of a balance on its cubic matrix (Table 12/16) with the
cubic row of Table 17 as point noise (8 samples a point), reduced as the refit pipeline does (zero
points, tare, tare outputs from a first cubic fit). Clean campaigns have no effect: any effect
named or anything `unexplained` is a false discovery. Effect campaigns inject one effect in one of
the
*alternative* shapes of simulation/effects.py (written from the physics, not from the candidate
terms) on one component of a group (forces F_X, F_Y, F_Z or moments M_X, M_Y, M_Z; the seed picks
the component and the shape), undeclared, with a size in noise floors: the RMS (% FS) the effect
adds to that component's cubic-fit residual, noise-free, divided by Table 17's cubic σ of it. Two
effects outside every family must come out as `unexplained` with nothing named. Prints markdown
tables (for the README) and the runtime.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache
import sys
import time

import numpy as np

from ..accuracy.sigma import sigma_pct_fs
from ..config import BalanceConfig, load_balance_config
from ..diagnosis.candidates import EFFECT_NAMES
from ..diagnosis.diagnose import diagnose, Diagnosis
from ..diagnosis.statistics import fit_columns
from ..fit.least_squares import fit_model
from ..model.tm663 import tm663_terms
from ..reduction import LoadPoints, reduce_points, Reduction, retare_with_model
from . import effects as sim_effects
from .balance_sim import simulate_campaign, SimulationSettings, table17_noise

BALANCES = ('lmc6522', 'b660h')
TARGET_COMPONENT = 'FX'
# A first guess of each effect's parameter (calibrated below), on the F_X bridge.
FIRST_GUESS = {
    'temperature': 1e-3,
    'zero_drift': 0.003,
    'hysteresis': 1e-3,
    'bidirectional': 1e-2,
    'cross_terms': 5.0,
    'tare': 1.0,
    'creep': 1e-3,
    'excitation': 1e-4,
}
COMPONENTS = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')
GROUPS = {'forces': ('FX', 'FY', 'FZ'), 'moments': ('MX', 'MY', 'MZ')}
# Shapes written from the physics in simulation/effects.py, not from the candidate terms: per
# family, the alternative forms the detection runs draw from (a seed picks one), and the two
# effects no family describes, which must come out as "unexplained".
ALTERNATIVE_SHAPES = {
    'temperature': ('temperature_dt2', 'temperature_lagged'),
    'hysteresis': ('hysteresis_play', 'hysteresis_turning'),
    'bidirectional': ('bidirectional_load_sign',),
    'creep': ('creep_two_constants',),
    'excitation': ('excitation_steps',),
    'zero_drift': ('zero_drift',),
    'cross_terms': ('cross_terms_other',),
    'tare': ('tare',),
}
OUTSIDE_SHAPES = ('outside_dead_band', 'outside_gravity_time')
FIRST_GUESS.update(
    {
        'temperature_dt2': 2e-4,
        'temperature_lagged': 1e-3,
        'hysteresis_play': 1e-3,
        'hysteresis_turning': 1e-3,
        'bidirectional_load_sign': 1e-3,
        'creep_two_constants': 1e-3,
        'excitation_steps': 1e-4,
        'cross_terms_other': 5.0,
        'outside_dead_band': 1e-3,
        'outside_gravity_time': 1e-3,
    }
)


def shape_family(shape: str | None) -> str | None:
    """The family a shape belongs to (None: outside every family)."""
    for family, shapes in ALTERNATIVE_SHAPES.items():
        if shape in shapes or shape == family:
            return family
    return None


def shape_effects(shape: str, parameter: float, component: str = TARGET_COMPONENT):
    """(effects, estimate_body_weight) for one alternative shape of the given parameter on one
    component.
    """
    k = COMPONENTS.index(component)
    bridge = np.zeros(6)
    bridge[k] = 1.0
    if shape in EFFECT_NAMES and shape not in ('creep', 'excitation'):
        return injected_effects(shape, parameter, component)
    if shape == 'temperature_dt2':
        return [sim_effects.TemperatureShapes(sensitivity_per_k2=parameter * bridge)], True
    if shape == 'temperature_lagged':
        return [
            sim_effects.TemperatureShapes(sensitivity_per_k=parameter * bridge, lag_s=2400.0)
        ], True
    if shape == 'hysteresis_play':
        return [
            sim_effects.PlayHysteresis(fraction_of_rated=parameter * bridge, width_fraction=0.2)
        ], True
    if shape == 'hysteresis_turning':
        return [sim_effects.TurningPointHysteresis(fraction_of_rated=parameter * bridge)], True
    if shape == 'bidirectional_load_sign':
        return [sim_effects.LoadSignBidirectional(asymmetry=parameter * bridge)], True
    if shape in ('creep_two_constants', 'creep'):
        return [
            sim_effects.Creep(fraction=parameter * bridge, time_constants_s=(40.0, 400.0))
        ], True
    if shape in ('excitation_steps', 'excitation'):
        return [
            sim_effects.SupplyDrift(
                gain_per_hour=parameter, steps=((0.55 * 328 * 90.0, 3 * parameter),)
            )
        ], True
    if shape == 'cross_terms_other':
        other = COMPONENTS[(k + 2) % 6]
        return [
            sim_effects.CrossTerms(
                coefficients={component: {f'{component}V*{other}V^2': parameter}}
            )
        ], True
    if shape == 'outside_dead_band':
        return [
            sim_effects.NeighbourDeadBand(
                fraction_of_rated=parameter, source=(k + 1) % 6, target=k
            )
        ], True
    if shape == 'outside_gravity_time':
        return [sim_effects.GravityTimeNonlinearity(fraction_of_rated=parameter * bridge)], True
    raise ValueError(f'unknown shape {shape!r}')


def injected_effects(name: str, parameter: float, component: str = TARGET_COMPONENT):
    """(effects, estimate_body_weight) for one effect of the given parameter on one bridge.

    temperature: sensitivity per K; zero_drift: amplitude mV (period 900 s); hysteresis: fraction
    of rated output; bidirectional: asymmetry; cross_terms: coefficient of FXV^2*FZV in F_X;
    tare: relative excess weight of the body (the body is declared, not estimated from the zero
    points, or the reduction would simply measure it).
    """
    bridge = np.zeros(6)
    bridge[('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ').index(component)] = 1.0
    if name == 'temperature':
        return [sim_effects.Temperature(sensitivity_per_k=parameter * bridge)], True
    if name == 'zero_drift':
        return [sim_effects.ZeroDrift(amplitude_mv=parameter * bridge)], True
    if name == 'hysteresis':
        return [sim_effects.Hysteresis(fraction_of_rated=parameter * bridge)], True
    if name == 'bidirectional':
        return [sim_effects.Bidirectional(asymmetry=parameter * bridge)], True
    if name == 'cross_terms':
        return [
            sim_effects.CrossTerms(coefficients={component: {f'{component}V^2*FZV': parameter}})
        ], True
    if name == 'tare':
        return [sim_effects.HeavierBody(weight_factor=1.0 + parameter)], False
    if name in ('creep', 'excitation'):
        return shape_effects(name, parameter, component)
    raise ValueError(f'unknown effect {name!r}; known: {", ".join(EFFECT_NAMES)}')


def simulate_reduction(
    config: BalanceConfig,
    effects=(),
    *,
    seed: int = 0,
    noise_scale: float = 1.0,
    estimate_body_weight: bool = True,
    retare: bool = True,
    samples_per_point: int = 1,
    with_scatter: bool = False,
):
    """A simulated campaign (Table 17 cubic noise x noise_scale), cut into points and reduced.

    With retare (as the refit pipeline does) the tare outputs come from the inverse of a first
    cubic fit instead of the linear eqs. (32)-(37). with_scatter: return (reduction, dict of
    diagnose()'s point_variance_mv2 and point_samples from the points' own samples).
    """
    settings = SimulationSettings(
        noise_sigma_pct_fs=table17_noise(config) * noise_scale,
        seed=seed,
        samples_per_point=samples_per_point,
    )
    campaign = simulate_campaign(config, settings=settings, effects=list(effects))
    means, times, temperatures = campaign.point_means()
    points = LoadPoints(
        campaign.point,
        means,
        times,
        temperatures,
        campaign.orientation,
        campaign.gravity,
        campaign.applied_loads,
    )
    reduction = reduce_points(points, config, estimate_body_weight=estimate_body_weight)
    if retare:
        terms = tm663_terms('cubic', config.bridge_outputs)
        corrected = reduction.corrected
        first = fit_model(
            terms,
            corrected.bridge_outputs_mv,
            corrected.loads,
            name='cubic',
            rated_outputs=config.rated_outputs_by_name,
            components=config.components,
            inputs=config.bridge_outputs,
            on_unexcited='drop',
        )
        reduction = retare_with_model(reduction, first.model)
    if with_scatter:
        variance, counts = campaign.point_scatter()
        return reduction, {'point_variance_mv2': variance, 'point_samples': counts}
    return reduction


def noise_floor_pct_fs(config: BalanceConfig) -> np.ndarray:
    """Table 17's cubic σ per component: the scatter a clean cubic fit reaches."""
    row = config.table17_sigma_pct_fs.get('cubic', {})
    return np.array([float(row.get(c, 0.0)) for c in config.components])


def _cubic_residuals(config: BalanceConfig, reduction: Reduction) -> np.ndarray:
    from ..model.terms import as_variables, design_matrix

    terms = tm663_terms('cubic', config.bridge_outputs)
    outputs = reduction.corrected.bridge_outputs_mv
    design = design_matrix(terms, as_variables(config.bridge_outputs, outputs), len(outputs))
    return np.column_stack(
        [
            fit_columns(design, reduction.corrected.loads[:, k]).residuals
            for k in range(len(config.components))
        ]
    )


def effect_size_pct_fs(
    config: BalanceConfig, name: str, parameter: float, component: str = TARGET_COMPONENT
) -> float:
    """RMS (% FS) the effect adds to the component's cubic-fit residual, noise-free."""
    k = config.components.index(component)
    effects, estimate = shape_effects(name, parameter, component)
    clean = _cubic_residuals(
        config, simulate_reduction(config, noise_scale=0.0, estimate_body_weight=estimate)
    )
    # (both retared the same way, so the difference is the effect's alone)
    dirty = _cubic_residuals(
        config, simulate_reduction(config, effects, noise_scale=0.0, estimate_body_weight=estimate)
    )
    return sigma_pct_fs(dirty[:, k] - clean[:, k], config.capacity[k])


@lru_cache(maxsize=None)
def calibrated_parameter(
    balance: str, name: str, noise_floors: float, component: str = TARGET_COMPONENT
) -> float:
    """The effect parameter whose size is `noise_floors` x Table 17's cubic σ of the component."""
    config = load_balance_config(balance)
    target = noise_floors * noise_floor_pct_fs(config)[config.components.index(component)]
    parameter = FIRST_GUESS[name]
    for _ in range(3):  # secant through the origin; the sizes are near-linear
        size = effect_size_pct_fs(config, name, parameter, component)
        if size <= 0:
            break
        parameter *= target / size
        if abs(size / target - 1.0) < 0.03:
            break
    return float(parameter)


# --- one campaign -----------------------------------------------------------------------------
@dataclass(frozen=True)
class Outcome:
    balance: str
    family: str | None  # the family injected (None: clean or outside every family)
    shape: str | None  # the simulated shape (None: clean)
    group: str  # 'forces', 'moments' or 'clean'
    component: str  # where it was injected (size measured there)
    noise_floors: float
    seed: int
    found: tuple[str, ...]
    unexplained: tuple[str, ...]  # components with an unexplained entry
    warnings: int
    sigma_before: float  # target component, in-sample, % FS
    sigma_after: float
    crossval_before: float
    crossval_after: float
    seconds: float
    # every component's σ before, in-sample and cross-validated (% FS): the clean floors
    sigma_before_all: Mapping[str, float] = field(default_factory=dict)
    crossval_before_all: Mapping[str, float] = field(default_factory=dict)

    @property
    def right(self) -> bool:
        """Right name first and no other name (a family), or nothing named and something
        unexplained (outside every family), or nothing at all (clean).
        """
        if self.shape is None:
            return not self.found and not self.unexplained
        if self.family is None:
            return not self.found and bool(self.unexplained)
        return self.found == (self.family,)


def run_one(
    balance: str,
    shape: str | None,
    noise_floors: float,
    seed: int,
    component: str = TARGET_COMPONENT,
    group: str = 'clean',
    scatter: bool = True,
) -> Outcome:
    config = load_balance_config(balance)
    if shape is None:
        effects, estimate = [], True
    else:
        effects, estimate = shape_effects(
            shape, calibrated_parameter(balance, shape, noise_floors, component), component
        )
    reduction, extra = simulate_reduction(
        config,
        effects,
        seed=seed,
        estimate_body_weight=estimate,
        samples_per_point=8,
        with_scatter=True,
    )
    start = time.perf_counter()
    result: Diagnosis = diagnose(reduction, config, **(extra if scatter else {}))
    seconds = time.perf_counter() - start
    c = component
    return Outcome(
        balance,
        shape_family(shape) if shape else None,
        shape,
        group,
        c,
        noise_floors,
        seed,
        result.effect_names,
        tuple(x for u in result.unexplained for x in u.components),
        len(result.warnings),
        result.sigma_pct_fs['before'][c],
        result.sigma_pct_fs['after'][c],
        result.sigma_pct_fs_crossval['before'][c],
        result.sigma_pct_fs_crossval['after'][c],
        seconds,
        dict(result.sigma_pct_fs['before']),
        dict(result.sigma_pct_fs_crossval['before']),
    )


def _run(args):
    return run_one(*args)


def jobs_for(balances, families, outside, sizes, seeds, clean_seeds, scatter=True) -> list[tuple]:
    """Clean campaigns, then per family / component group / balance / size `seeds` campaigns; seed
    s puts the effect on the group's component s mod 3 in the family's shape s mod (number of
    shapes).
    """
    jobs = [
        (b, None, 0.0, 1000 + s, TARGET_COMPONENT, 'clean', scatter)
        for b in balances
        for s in range(clean_seeds)
    ]
    for b in balances:
        for name in list(families) + list(outside):
            shapes = ALTERNATIVE_SHAPES.get(name, (name,))
            groups = {'all': ('FX',)} if name == 'tare' else GROUPS
            for group, members in groups.items():
                for size in sizes:
                    for s in range(seeds):
                        jobs.append(
                            (
                                b,
                                shapes[s % len(shapes)],
                                size,
                                2000 + s,
                                members[s % len(members)],
                                group,
                                scatter,
                            )
                        )
    return jobs


# --- tables -----------------------------------------------------------------------------------
def markdown_tables(outcomes: list[Outcome], floors: dict, sizes, balances) -> str:
    lines = []
    names = {b: load_balance_config(b).name for b in balances}
    lines.append(
        'Clean campaigns (cubic truth, Table 17 cubic noise, no effect): campaigns with any '
        'effect named or anything `unexplained`:\n'
    )
    lines.append('| balance | campaigns | effect named | unexplained | warnings |')
    lines.append('|---|---|---|---|---|')
    for b in balances:
        clean = [o for o in outcomes if o.balance == b and o.shape is None]
        if clean:
            named = sorted({n for o in clean for n in o.found})
            lines.append(
                f'| {names[b]} | {len(clean)} | {sum(1 for o in clean if o.found)}'
                + (f' ({", ".join(named)})' if named else '')
                + (
                    f' | {sum(1 for o in clean if o.unexplained)} | '
                    f'{sum(1 for o in clean if o.warnings)} |'
                )
            )
    lines.append('')
    lines.append(
        'Alternative shapes (simulation/effects.py, not the candidate terms), one effect per '
        'campaign on '
        "the group's components in turn, size in Table 17 noise floors of that component. Cell: "
        'campaigns with the right name first and no other name (outside effects: nothing named '
        'and '
        '`unexplained` non-empty) / campaigns; then σ after / clean floor, in-sample and '
        "cross-validated (median over the cell's campaigns; the clean floor is the median σ of "
        "that "
        'component on the clean campaigns):\n'
    )
    header = (
        '| effect | shapes | '
        + ' | '.join(f'{names[b]} {g} {s:g}x' for b in balances for g in GROUPS for s in sizes)
        + ' |'
    )
    lines.append(header)
    lines.append('|---' * (2 + len(balances) * len(GROUPS) * len(sizes)) + '|')
    keys = list(ALTERNATIVE_SHAPES) + list(OUTSIDE_SHAPES)
    for name in keys:
        runs_all = [o for o in outcomes if (o.shape in ALTERNATIVE_SHAPES.get(name, (name,)))]
        if not runs_all:
            continue
        cells = []
        for b in balances:
            for g in GROUPS:
                for size in sizes:
                    runs = [
                        o
                        for o in runs_all
                        if o.balance == b
                        and o.noise_floors == size
                        and (o.group == g or (o.group == 'all' and g == 'forces'))
                    ]
                    if not runs:
                        cells.append('')
                        continue
                    right = sum(o.right for o in runs)
                    ratio = np.median(
                        [o.sigma_after / floors[(b, o.component, 'sigma')] for o in runs]
                    )
                    ratio_cv = np.median(
                        [o.crossval_after / floors[(b, o.component, 'crossval')] for o in runs]
                    )
                    wrong = sorted(
                        {n for o in runs for n in o.found}
                        - ({shape_family(runs[0].shape)} - {None})
                    )
                    cells.append(
                        f'{right}/{len(runs)}; {ratio:.2f}, CV {ratio_cv:.2f}'
                        + (f' (also: {", ".join(wrong)})' if wrong else '')
                    )
        shapes = ', '.join(ALTERNATIVE_SHAPES.get(name, (name,)))
        lines.append(f'| {name} | {shapes} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


def floors_from_clean(outcomes: Sequence[Outcome]) -> dict:
    """(balance, component, 'sigma'|'crossval') -> median σ over the clean campaigns (% FS)."""
    floors = {}
    for b in dict.fromkeys(o.balance for o in outcomes if o.shape is None):
        clean = [o for o in outcomes if o.balance == b and o.shape is None]
        for c in clean[0].sigma_before_all:
            floors[(b, c, 'sigma')] = float(np.median([o.sigma_before_all[c] for o in clean]))
            floors[(b, c, 'crossval')] = float(
                np.median([o.crossval_before_all[c] for o in clean])
            )
    return floors


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split('\n')[0]
        + ': clean campaigns, one effect in an alternative shape per '
        'campaign, and two effects outside every family; prints markdown tables and the runtime.'
    )
    parser.add_argument(
        '--balances',
        nargs='+',
        default=list(BALANCES),
        metavar='NAME',
        help='balance configs to run (default: lmc6522 b660h)',
    )
    parser.add_argument(
        '--clean-seeds',
        type=int,
        default=50,
        metavar='N',
        help='clean campaigns per balance (default 50)',
    )
    parser.add_argument(
        '--seeds',
        type=int,
        default=10,
        metavar='N',
        help='campaigns per family, component group, balance and size (default 10)',
    )
    parser.add_argument(
        '--sizes',
        type=float,
        nargs='+',
        default=[1.0],
        metavar='FLOORS',
        help='effect sizes in Table 17 noise floors of the component (default 1)',
    )
    parser.add_argument(
        '--families',
        nargs='+',
        default=list(ALTERNATIVE_SHAPES),
        metavar='FAMILY',
        help='families to inject: ' + ', '.join(ALTERNATIVE_SHAPES) + ' (default all)',
    )
    parser.add_argument(
        '--outside',
        nargs='*',
        default=list(OUTSIDE_SHAPES),
        metavar='SHAPE',
        help='effects outside every family: ' + ', '.join(OUTSIDE_SHAPES) + ' (default both; '
        'none with an empty list)',
    )
    parser.add_argument(
        '--zero-points-only',
        action='store_true',
        help='repeatability from the zero points alone (no per-point sample scatter)',
    )
    parser.add_argument(
        '--jobs', type=int, default=2, metavar='N', help='worker processes (default 2)'
    )
    args = parser.parse_args(argv)
    if args.jobs < 1 or args.seeds < 0 or args.clean_seeds < 0:
        parser.error('--jobs must be at least 1, --seeds and --clean-seeds at least 0')
    if args.clean_seeds < 1 and args.seeds > 0 and (args.families or args.outside):
        parser.error('--clean-seeds must be at least 1: the σ floors come from clean campaigns')
    start = time.perf_counter()
    scatter = not args.zero_points_only
    jobs = jobs_for(
        args.balances,
        args.families,
        args.outside,
        args.sizes,
        args.seeds,
        args.clean_seeds,
        scatter,
    )
    for b, shape, size, _, component, _, _ in jobs:  # calibrate sizes once (cached)
        if shape is not None:
            calibrated_parameter(b, shape, size, component)
    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as pool:
            outcomes = list(pool.map(_run, jobs, chunksize=4))
    else:
        outcomes = [_run(j) for j in jobs]
    floors = floors_from_clean(outcomes)
    elapsed = time.perf_counter() - start
    print(markdown_tables(outcomes, floors, args.sizes, args.balances))
    print(
        f'\n{len(outcomes)} campaigns in {elapsed:.0f} s wall ({args.jobs} jobs); '
        f'diagnose() {np.mean([o.seconds for o in outcomes]):.2f} s per campaign on average.'
    )
    return 0


if __name__ == '__main__':
    sys.exit(main())
