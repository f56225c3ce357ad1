#!/usr/bin/env python3
"""Two effects at once over ten seeds: the cases of
test/diagnosis/test_diagnosis_two_effects.py, each effect one floor on its own component; prints
one line a case and the total (docs/results.md).
    python tools/two_effects_cells.py [--seeds 10] [--jobs 2]
A campaign is right when exactly the two families are named, nothing is `unexplained`, and σ
after on both components is at most 1.15x the clean campaign of the same seed.
"""

import argparse
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
import sys
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

import diagnosis_physics as physics  # noqa: E402
from physics_cells import _campaign  # noqa: E402  (the same campaign as the shapes' table)
from test_diagnosis_two_effects import CASES  # noqa: E402

TARGET = 1.15


def one_seed(args) -> list[tuple]:
    """Every case's outcome for one balance and seed: (case, right, worst σ ratio, names)."""
    balance, seed = args
    _, clean = _campaign(balance, [], seed)
    out = []
    for index, (case_balance, parts) in enumerate(CASES):
        if case_balance != balance:
            continue
        _, result = _campaign(balance, [physics.scaled(balance, s, c) for s, c in parts], seed)
        families = {physics.FAMILY[s] for s, _ in parts}
        sigma = max(
            result.sigma_pct_fs['after'][c] / clean.sigma_pct_fs['before'][c] for _, c in parts
        )
        named = set(result.effect_names) == families and len(result.effect_names) == 2
        right = named and not result.unexplained and sigma <= TARGET
        names = result.effect_names + (('unexplained',) if result.unexplained else ())
        out.append((index, right, sigma, names))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--seeds', type=int, default=10)
    parser.add_argument('--jobs', type=int, default=2)
    args = parser.parse_args(argv)
    start = time.perf_counter()
    jobs = [(b, s) for b in ('lmc6522', 'b660h') for s in range(3000, 3000 + args.seeds)]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = [row for part in pool.map(one_seed, jobs) for row in part]
    for index, (balance, parts) in enumerate(CASES):
        cell = [r for r in rows if r[0] == index]
        misses = sorted({n for r in cell if not r[1] for n in r[3]})
        what = ' + '.join(f'{s} on {c}' for s, c in parts)
        print(
            f'{balance} {what}: {sum(r[1] for r in cell)}/{len(cell)} right, '
            f'σ ≤ {max(r[2] for r in cell):.2f}'
            + (f' (misses: {", ".join(misses)})' if misses else '')
        )
    print(
        f'{sum(r[1] for r in rows)}/{len(rows)} right; {len(rows) + len(jobs)} campaigns in '
        f'{time.perf_counter() - start:.0f} s ({args.jobs} jobs)'
    )
    return 0


if __name__ == '__main__':
    sys.exit(main())
