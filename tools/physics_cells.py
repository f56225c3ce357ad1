#!/usr/bin/env python3
"""The issue-24 table: loops and sign asymmetries written from their physics
(test/diagnosis_physics.py) at one noise floor, on one bridge and on every bridge of each balance,
ten seeds a cell; prints a markdown table (docs/results.md).
    python tools/physics_cells.py [--seeds 10] [--jobs 2]
A campaign is right when the shape's family (test/diagnosis_physics.FAMILY; friction's is
hysteresis) is named first and alone and nothing is `unexplained`; it meets the
target when it is right and σ after, in-sample and cross-validated, is at most 1.15x the clean
campaign of the same seed on every affected component (test_diagnosis_physics_shapes.py holds the
cells that meet it in CI).
"""

import argparse
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
import sys
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

import diagnosis_physics as physics  # noqa: E402

from balance_calib.config import load_balance_config  # noqa: E402
from balance_calib.diagnosis import diagnose  # noqa: E402
from balance_calib.simulation.diagnosis_rates import simulate_reduction  # noqa: E402

SHAPES = (
    'preisach', 'masing', 'bouc_wen', 'reseating', 'friction', 'sign_step', 'negative_curvature',
)
WHERE = (('lmc6522', 'MY'), ('lmc6522', 'all'), ('b660h', 'FZ'), ('b660h', 'all'))
TARGET = 1.15


def _campaign(balance, effects, seed):
    config = load_balance_config(balance)
    reduction, scatter = simulate_reduction(
        config, effects, seed=seed, samples_per_point=8, with_scatter=True
    )
    return config, diagnose(reduction, config, **scatter)


def one_seed(args) -> list[tuple]:
    """Every cell's outcome for one balance and seed: (shape, bridges, right, σ, CV, names)."""
    balance, seed = args
    _, clean = _campaign(balance, [], seed)
    out = []
    for shape in SHAPES:
        for where_balance, bridges in WHERE:
            if where_balance != balance:
                continue
            config, result = _campaign(balance, [physics.scaled(balance, shape, bridges)], seed)
            components = config.components if bridges == 'all' else (bridges,)
            sigma = max(
                result.sigma_pct_fs['after'][c] / clean.sigma_pct_fs['before'][c]
                for c in components
            )
            crossval = max(
                result.sigma_pct_fs_crossval['after'][c]
                / clean.sigma_pct_fs_crossval['before'][c]
                for c in components
            )
            family = physics.FAMILY[shape]
            right = result.effect_names == (family,) and not result.unexplained
            names = result.effect_names + (('unexplained',) if result.unexplained else ())
            out.append((shape, bridges, right, sigma, crossval, names))
    return [(balance,) + o for o in out]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--seeds', type=int, default=10)
    parser.add_argument('--jobs', type=int, default=2)
    args = parser.parse_args(argv)
    seeds = range(3000, 3000 + args.seeds)
    start = time.perf_counter()
    jobs = [(b, s) for b in ('lmc6522', 'b660h') for s in seeds]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = [row for part in pool.map(one_seed, jobs) for row in part]
    print('| shape | ' + ' | '.join(f'{b.upper()} {w}' for b, w in WHERE) + ' |')
    print('|---' * (len(WHERE) + 1) + '|')
    for shape in SHAPES:
        cells = []
        for balance, bridges in WHERE:
            cell = [r for r in rows if r[0] == balance and r[1] == shape and r[2] == bridges]
            right = sum(r[3] for r in cell)
            met = sum(r[3] and r[4] <= TARGET and r[5] <= TARGET for r in cell)
            sigma, crossval = max(r[4] for r in cell), max(r[5] for r in cell)
            others = sorted({n for r in cell if not r[3] for n in r[6]})
            text = f'{met}/{len(cell)} met, {right} right; σ ≤ {sigma:.2f}, CV ≤ {crossval:.2f}'
            if others:
                text += f' (misses: {", ".join(others)})'
            cells.append(text)
        print(f'| {shape} | ' + ' | '.join(cells) + ' |')
    print(f'\n{len(rows)} campaigns in {time.perf_counter() - start:.0f} s ({args.jobs} jobs)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
