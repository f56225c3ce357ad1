"""Fit time of a 2 000-point, 96-term iterative (AIAA R-091) calibration beside the direct
(TM-663 cubic) one on the same data, the time of `fit --method auto` (model selection over both
forms and four term sets) against one direct fit, and the per-sample cost of evaluating each.

    python -m balance_calib.benchmarks.fit_speed [--points 2000] [--repeat 3]

The data: a generated table (R-091 96-term truth, output noise, one tare per load series); both
fits estimate the series tares with the model. Times are the best of --repeat runs, this process,
term statistics (VIF, significance, PRESS per term) included and excluded.
"""

from __future__ import annotations

import argparse
import platform

from .timing import best_of as _best_of


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--points', type=int, default=2000)
    parser.add_argument('--repeat', type=int, default=3)
    args = parser.parse_args(argv)

    import numpy as np

    from balance_calib.fit.iterative import fit_iterative
    from balance_calib.fit.series_tares import fit_direct
    from balance_calib.model.r091 import r091_terms, tm663_cubic_terms
    from balance_calib.tables import synthetic as sy

    rng = np.random.default_rng(1)
    truth = sy.iterative_truth(rng)
    pair_points = max(-(-(args.points - 6 * 21) // 15), 10)  # ceil: at least --points points
    schedule = sy.support_schedule(rng, 21, pair_points)
    tares = sy.tares_for(rng, np.unique(schedule.series))
    applied, outputs = sy.iterative_campaign(rng, truth, schedule, tares, 0.0006)
    n_series = len(np.unique(schedule.series))
    iterative_terms, direct_terms = r091_terms(sy.LOADS), tm663_cubic_terms(sy.OUTPUTS)
    print(
        f'{platform.machine()}, Python {platform.python_version()}, numpy {np.__version__}; '
        f'{len(applied)} points, {n_series} load series (one tare each)'
    )

    def iterative(statistics):
        return fit_iterative(
            iterative_terms,
            applied,
            outputs,
            schedule.series,
            components=sy.LOADS,
            inputs=sy.OUTPUTS,
            capacity=sy.capacity_si(),
            statistics=statistics,
        )

    def direct(statistics, terms=direct_terms):
        return fit_direct(
            terms,
            outputs,
            applied,
            schedule.series,
            components=sy.LOADS,
            inputs=sy.OUTPUTS,
            statistics=statistics,
        )

    fit = iterative(False)
    rows = [
        (
            f'iterative, r091-96 ({len(iterative_terms)} terms), tares iterated '
            f'({fit.iterations} iterations)',
            _best_of(lambda: iterative(False), args.repeat),
            _best_of(lambda: iterative(True), args.repeat),
        ),
        (
            f'direct, tm663-cubic ({len(direct_terms)} terms), tares as intercepts',
            _best_of(lambda: direct(False), args.repeat),
            _best_of(lambda: direct(True), args.repeat),
        ),
        (
            f'direct, r091-96 on the outputs ({len(iterative_terms)} terms)',
            _best_of(lambda: direct(False, r091_terms(sy.OUTPUTS)), args.repeat),
            _best_of(lambda: direct(True, r091_terms(sy.OUTPUTS)), args.repeat),
        ),
    ]
    print(f'{"fit":72}  {"fit (s)":>8}  {"+ term stats (s)":>16}')
    for label, bare, with_stats in rows:
        print(f'{label:72}  {bare:8.3f}  {with_stats:16.3f}')

    from balance_calib.tables.calibrate import calibrate_table

    table = sy.make_table(applied, outputs, schedule.series)
    auto = calibrate_table(table, force=True)
    one = _best_of(lambda: direct(True), args.repeat)
    whole = _best_of(lambda: calibrate_table(table, force=True), args.repeat)
    candidates = auto.report['model_selection']['candidates']
    term_sets = ', '.join(sorted({c['term_set'] for c in candidates}))
    print(
        f'\n--method auto --terms auto: {len(candidates)} candidates '
        f'(both forms x {term_sets}), '
        f'PRESS pruning, gates; adopted {auto.method} {auto.report["term_set"]} '
        f'({len(auto.report["terms"])} terms)'
    )
    print(f'{"auto, the whole calibrate_table (s)":72}  {whole:8.3f}')
    print(f'{"one direct tm663-cubic fit with term statistics (s)":72}  {one:8.3f}')
    print(f'{"ratio":72}  {whole / one:8.1f}')

    direct_model = direct(False).model
    batch = outputs[:1000]
    print(
        f'\n{"evaluation (loads from outputs)":40}  {"1 sample (µs)":>14}  '
        f'{"batch of 1000 (µs/sample)":>26}'
    )
    for label, model in (
        ('iterative (Newton, vectorised)', fit.model),
        ('direct (polynomial)', direct_model),
    ):
        single = (
            _best_of(lambda: [model.loads(batch[i : i + 1]) for i in range(200)], args.repeat)
            / 200
        )
        many = _best_of(lambda: model.loads(batch), args.repeat) / len(batch)
        print(f'{label:40}  {single * 1e6:14.1f}  {many * 1e6:26.2f}')


if __name__ == '__main__':
    main()
