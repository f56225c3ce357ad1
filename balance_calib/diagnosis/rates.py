"""Detection and false-discovery rates of the residual diagnosis on simulated campaigns.

    launchless_scripts/diagnosis_rates [--clean-seeds 20] [--seeds 10] [--sizes 0.5 1 2] [--jobs 2]

Every campaign is the Appendix A/B schedule of a balance on its cubic matrix (Table 12/16) with the
cubic row of Table 17 as point noise, reduced as the refit pipeline does (zero points, tare, tare
outputs from a first cubic fit). Clean campaigns have no effect: any effect found is a false
discovery. Effect campaigns inject one effect on the F_X bridge, undeclared, with a size given in
noise floors: the RMS (% FS) that the effect adds to the F_X residual of the cubic fit, noise-free,
divided by Table 17's cubic σ_FX. Prints markdown tables (for the README) and the runtime.
"""
from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..config import BalanceConfig, load_balance_config
from ..model.tm663 import tm663_terms
from ..fit.least_squares import fit_model
from ..reduction import LoadPoints, Reduction, reduce_points, retare_with_model
from ..simulation import effects as sim_effects
from ..simulation.balance_sim import SimulationSettings, simulate_campaign, table17_noise
from .candidates import EFFECT_NAMES
from .diagnose import Diagnosis, diagnose
from .statistics import fit_columns

BALANCES = ('lmc6522', 'b660h')
TARGET_COMPONENT = 'FX'
# A first guess of each effect's parameter (calibrated below), on the F_X bridge.
FIRST_GUESS = {'temperature': 1e-3, 'zero_drift': 0.003, 'hysteresis': 1e-3, 'bidirectional': 1e-2,
               'cross_terms': 5.0, 'tare': 1.0, 'creep': 1e-3, 'excitation': 1e-4}
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
FIRST_GUESS.update({'temperature_dt2': 2e-4, 'temperature_lagged': 1e-3, 'hysteresis_play': 1e-3,
                    'hysteresis_turning': 1e-3, 'bidirectional_load_sign': 1e-3, 'creep_two_constants': 1e-3,
                    'excitation_steps': 1e-4, 'cross_terms_other': 5.0, 'outside_dead_band': 1e-3,
                    'outside_gravity_time': 1e-3})


def shape_family(shape: str) -> str | None:
    """The family a shape belongs to (None: outside every family)."""
    for family, shapes in ALTERNATIVE_SHAPES.items():
        if shape in shapes or shape == family:
            return family
    return None


def shape_effects(shape: str, parameter: float, component: str = TARGET_COMPONENT):
    """(effects, estimate_body_weight) for one alternative shape of the given parameter on one component."""
    k = COMPONENTS.index(component)
    bridge = np.zeros(6)
    bridge[k] = 1.0
    if shape in EFFECT_NAMES and shape not in ('creep', 'excitation'):
        return injected_effects(shape, parameter, component)
    if shape == 'temperature_dt2':
        return [sim_effects.TemperatureShapes(sensitivity_per_k2=parameter * bridge)], True
    if shape == 'temperature_lagged':
        return [sim_effects.TemperatureShapes(sensitivity_per_k=parameter * bridge, lag_s=2400.0)], True
    if shape == 'hysteresis_play':
        return [sim_effects.PlayHysteresis(fraction_of_rated=parameter * bridge, width_fraction=0.3)], True
    if shape == 'hysteresis_turning':
        return [sim_effects.TurningPointHysteresis(fraction_of_rated=parameter * bridge)], True
    if shape == 'bidirectional_load_sign':
        return [sim_effects.LoadSignBidirectional(asymmetry=parameter * bridge)], True
    if shape in ('creep_two_constants', 'creep'):
        return [sim_effects.Creep(fraction=parameter * bridge, time_constants_s=(40.0, 400.0))], True
    if shape in ('excitation_steps', 'excitation'):
        return [sim_effects.SupplyDrift(gain_per_hour=parameter, steps=((0.55 * 328 * 90.0, 3 * parameter),))], True
    if shape == 'cross_terms_other':
        other = COMPONENTS[(k + 2) % 6]
        return [sim_effects.CrossTerms(coefficients={component: {f'{component}V*{other}V^2': parameter}})], True
    if shape == 'outside_dead_band':
        return [sim_effects.NeighbourDeadBand(fraction_of_rated=parameter, source=(k + 1) % 6, target=k)], True
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
        return [sim_effects.CrossTerms(coefficients={component: {f'{component}V^2*FZV': parameter}})], True
    if name == 'tare':
        return [sim_effects.HeavierBody(weight_factor=1.0 + parameter)], False
    if name in ('creep', 'excitation'):
        return shape_effects(name, parameter, component)
    raise ValueError(f'unknown effect {name!r}; known: {", ".join(EFFECT_NAMES)}')


def simulate_reduction(config: BalanceConfig, effects=(), *, seed: int = 0, noise_scale: float = 1.0,
                       estimate_body_weight: bool = True, retare: bool = True, samples_per_point: int = 1,
                       with_scatter: bool = False):
    """A simulated campaign (Table 17 cubic noise x noise_scale), cut into points and reduced.

    With retare (as the refit pipeline does) the tare outputs come from the inverse of a first
    cubic fit instead of the linear eqs. (32)-(37). with_scatter: return (reduction, dict of
    diagnose()'s point_variance_mv2 and point_samples from the points' own samples).
    """
    settings = SimulationSettings(noise_sigma_pct_fs=table17_noise(config) * noise_scale, seed=seed,
                                  samples_per_point=samples_per_point)
    campaign = simulate_campaign(config, settings=settings, effects=list(effects))
    means, times, temperatures = campaign.point_means()
    points = LoadPoints(campaign.point, means, times, temperatures, campaign.orientation, campaign.gravity,
                        campaign.applied_loads)
    reduction = reduce_points(points, config, estimate_body_weight=estimate_body_weight)
    if retare:
        terms = tm663_terms('cubic', config.bridge_outputs)
        corrected = reduction.corrected
        first = fit_model(terms, corrected.bridge_outputs_mv, corrected.loads, name='cubic',
                          rated_outputs=config.rated_outputs_by_name, components=config.components,
                          inputs=config.bridge_outputs, on_unexcited='drop')
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
    return np.column_stack([fit_columns(design, reduction.corrected.loads[:, k]).residuals
                            for k in range(len(config.components))])


def effect_size_pct_fs(config: BalanceConfig, name: str, parameter: float,
                       component: str = TARGET_COMPONENT) -> float:
    """RMS (% FS) the effect adds to the component's cubic-fit residual, noise-free."""
    k = config.components.index(component)
    effects, estimate = shape_effects(name, parameter, component)
    clean = _cubic_residuals(config, simulate_reduction(config, noise_scale=0.0, estimate_body_weight=estimate))
    # (both retared the same way, so the difference is the effect's alone)
    dirty = _cubic_residuals(config, simulate_reduction(config, effects, noise_scale=0.0,
                                                        estimate_body_weight=estimate))
    return float(np.sqrt(np.mean((dirty[:, k] - clean[:, k]) ** 2)) / config.capacity[k] * 100.0)


@lru_cache(maxsize=None)
def calibrated_parameter(balance: str, name: str, noise_floors: float, component: str = TARGET_COMPONENT) -> float:
    """The effect parameter whose size is `noise_floors` x Table 17's cubic σ of the component."""
    config = load_balance_config(balance)
    target = noise_floors * noise_floor_pct_fs(config)[config.components.index(component)]
    parameter = FIRST_GUESS[name]
    for _ in range(3):                       # secant through the origin; the sizes are near-linear
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
    effect: str | None          # injected (None: clean)
    noise_floors: float
    seed: int
    found: tuple[str, ...]
    first_components: tuple[str, ...]
    sigma_before: float         # target component, in-sample
    sigma_after: float
    crossval_before: float
    crossval_after: float
    seconds: float


def run_one(balance: str, effect: str | None, noise_floors: float, seed: int) -> Outcome:
    config = load_balance_config(balance)
    if effect is None:
        effects, estimate = [], True
    else:
        effects, estimate = injected_effects(effect, calibrated_parameter(balance, effect, noise_floors))
    reduction = simulate_reduction(config, effects, seed=seed, estimate_body_weight=estimate)
    start = time.perf_counter()
    result: Diagnosis = diagnose(reduction, config)
    seconds = time.perf_counter() - start
    c = TARGET_COMPONENT
    return Outcome(balance, effect, noise_floors, seed, result.effect_names,
                   result.effects[0].components if result.effects else (),
                   result.sigma_pct_fs['before'][c], result.sigma_pct_fs['after'][c],
                   result.sigma_pct_fs_crossval['before'][c], result.sigma_pct_fs_crossval['after'][c], seconds)


def _run(args):
    return run_one(*args)


# --- tables -----------------------------------------------------------------------------------
def _grid(outcomes, effect, balances, sizes, cell) -> list[str]:
    """One table row: cell(runs, effect) for every balance and size ('' where nothing ran)."""
    cells = []
    for b in balances:
        for s in sizes:
            runs = [o for o in outcomes if o.balance == b and o.effect == effect and o.noise_floors == s]
            cells.append(cell(runs, effect) if runs else '')
    return cells


def markdown_tables(outcomes: list[Outcome], sizes, balances) -> str:
    lines = []
    names = {b: load_balance_config(b).name for b in balances}
    lines.append('False discoveries on clean campaigns (cubic truth, Table 17 cubic noise, no effect):\n')
    lines.append('| balance | campaigns | with any effect found | false-discovery rate | effects found |')
    lines.append('|---|---|---|---|---|')
    for b in balances:
        clean = [o for o in outcomes if o.balance == b and o.effect is None]
        if not clean:
            continue
        hits = [o for o in clean if o.found]
        what = ', '.join(sorted({n for o in hits for n in o.found})) or '-'
        lines.append(f'| {names[b]} | {len(clean)} | {len(hits)} | {len(hits) / len(clean):.0%} | {what} |')
    lines.append('')
    lines.append('Detection: campaigns where the injected effect is named first (and found at all), '
                 'effect on the F_X bridge, size in Table 17 noise floors of σ_FX; last column: campaigns '
                 'where another effect was named too (all sizes and balances):\n')
    header = ('| effect | ' + ' | '.join(f'{names[b]} {s:g}x' for b in balances for s in sizes)
              + ' | also named |')
    lines.append(header)
    lines.append('|---' * (2 + len(balances) * len(sizes)) + '|')
    def detection(runs, effect):
        first = sum(1 for o in runs if o.found[:1] == (effect,))
        return f'{first}/{len(runs)} ({sum(1 for o in runs if effect in o.found)})'

    for effect in EFFECT_NAMES:
        cells = _grid(outcomes, effect, balances, sizes, detection)
        runs = [o for o in outcomes if o.effect == effect]
        extra = [o for o in runs if set(o.found) - {effect}]
        others = ', '.join(sorted({n for o in extra for n in o.found} - {effect}))
        cells.append(f'{len(extra)}/{len(runs)}' + (f' ({others})' if others else ''))
        lines.append(f'| {effect} | ' + ' | '.join(cells) + ' |')
    lines.append('')
    lines.append('σ_FX (% FS) before -> after, in-sample and cross-validated (PRESS), median over seeds:\n')
    lines.append('| effect | ' + ' | '.join(f'{names[b]} {s:g}x' for b in balances for s in sizes) + ' |')
    lines.append('|---' * (1 + len(balances) * len(sizes)) + '|')
    def sigmas(runs, effect):
        med = lambda attr: float(np.median([getattr(o, attr) for o in runs]))
        return (f'{med("sigma_before"):.3f}→{med("sigma_after"):.3f} '
                f'(CV {med("crossval_before"):.3f}→{med("crossval_after"):.3f})')

    for effect in EFFECT_NAMES:
        cells = _grid(outcomes, effect, balances, sizes, sigmas)
        lines.append(f'| {effect} | ' + ' | '.join(cells) + ' |')
    lines.append('')
    lines.append('Injected parameters (F_X bridge):\n')
    lines.append('| effect | parameter | ' + ' | '.join(f'{names[b]} {s:g}x' for b in balances for s in sizes) + ' |')
    lines.append('|---' * (2 + len(balances) * len(sizes)) + '|')
    meaning = {'temperature': 'sensitivity per K', 'zero_drift': 'amplitude, mV (900 s)',
               'hysteresis': 'fraction of rated output', 'bidirectional': 'asymmetry b (V += b·abs(V))',
               'cross_terms': 'FXV²·FZV coefficient, N/mV³', 'tare': 'excess body weight (declared body)'}
    for effect in EFFECT_NAMES:
        cells = [f'{calibrated_parameter(b, effect, s):.3g}' for b in balances for s in sizes]
        lines.append(f'| {effect} | {meaning[effect]} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--balances', nargs='+', default=list(BALANCES))
    parser.add_argument('--clean-seeds', type=int, default=20)
    parser.add_argument('--seeds', type=int, default=10, help='seeds per effect and size')
    parser.add_argument('--sizes', type=float, nargs='+', default=[0.5, 1.0, 2.0])
    parser.add_argument('--effects', nargs='+', default=list(EFFECT_NAMES))
    parser.add_argument('--jobs', type=int, default=2)
    args = parser.parse_args(argv)
    start = time.perf_counter()
    jobs = [(b, None, 0.0, 1000 + s) for b in args.balances for s in range(args.clean_seeds)]
    jobs += [(b, e, size, 2000 + s) for b in args.balances for e in args.effects for size in args.sizes
             for s in range(args.seeds)]
    # calibrate sizes once here (cached per process; workers recompute cheaply otherwise)
    for b in args.balances:
        for e in args.effects:
            for size in args.sizes:
                calibrated_parameter(b, e, size)
    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as pool:
            outcomes = list(pool.map(_run, jobs, chunksize=4))
    else:
        outcomes = [_run(j) for j in jobs]
    elapsed = time.perf_counter() - start
    print(markdown_tables(outcomes, args.sizes, args.balances))
    diagnose_time = np.mean([o.seconds for o in outcomes])
    print(f'\n{len(outcomes)} campaigns in {elapsed:.0f} s wall ({args.jobs} jobs); '
          f'diagnose() {diagnose_time:.2f} s per campaign on average.')
    return 0


if __name__ == '__main__':
    sys.exit(main())
