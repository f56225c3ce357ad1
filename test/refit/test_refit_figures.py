"""The refit's figures come after its record: calibration.yaml, report.json and
report.md are in place before any figure is drawn, a figure that fails is said and costs nothing
else, and a long series is decimated to what a panel can show.
"""

import json

import numpy as np

from balance_calib.calibrate.records import bag_record
from balance_calib.calibrate.write_record import write_record
from balance_calib.calibration_file import load_calibration
from balance_calib.calibration_settings import CalibrationSettings, RecordOptions
from balance_calib.figure_png import decimated, draw_figures
from balance_calib.refit import plots
from balance_calib.refit.pipeline import calibrate_points


def _result(campaigns, lmc6522):
    return calibrate_points(
        campaigns.points(seed=5), lmc6522, settings=CalibrationSettings(diagnose=False)
    )


def test_record_is_written_before_the_figures(campaigns, lmc6522, tmp_path):
    out = tmp_path / 'out'
    seen = {}

    def written(directory):
        seen['files'] = sorted(p.name for p in directory.iterdir() if not p.name.startswith('.'))
        seen['plots'] = json.loads((directory / 'report.json').read_text())['plots']

    write_record(
        bag_record(_result(campaigns, lmc6522)),
        RecordOptions(out, written=lambda _, directory: written(directory)),
    )
    models = ['residuals_linear.png', 'residuals_quadratic.png', 'residuals_cubic.png']
    assert seen['files'] == ['calibration.yaml', 'report.json', 'report.md']
    assert seen['plots'] == models  # report.md's links are known before the figures exist
    assert sorted(p.name for p in out.glob('*.png')) == sorted(models)
    assert not [p for p in out.iterdir() if p.name.startswith('.')]  # no staging left behind


def test_a_failed_figure_is_said_and_loses_nothing_else(campaigns, lmc6522, tmp_path, monkeypatch):
    original = plots.figure_plan

    def broken_quadratic(result):
        plan = original(result)

        def fail(path):
            raise RuntimeError('no fonts\nat all')

        return [(n, fail if n == 'residuals_quadratic.png' else d) for n, d in plan]

    monkeypatch.setattr(plots, 'figure_plan', broken_quadratic)
    said = []
    result = _result(campaigns, lmc6522)
    out = write_record(bag_record(result), RecordOptions(tmp_path / 'out'), said.append)
    assert load_calibration(out / 'calibration.yaml').model().name == 'cubic'
    report = json.loads((out / 'report.json').read_text())
    assert report['plots'] == ['residuals_linear.png', 'residuals_cubic.png']
    warning = [w for w in report['warnings'] if 'residuals_quadratic.png' in w]
    assert len(warning) == 1 and 'RuntimeError: no fonts at all' in warning[0]
    assert said == warning
    markdown = (out / 'report.md').read_text()
    assert '(residuals_quadratic.png)' not in markdown
    assert '![residuals_cubic.png](residuals_cubic.png)' in markdown
    assert sorted(p.name for p in out.glob('*.png')) == [
        'residuals_cubic.png',
        'residuals_linear.png',
    ]


def test_short_series_are_drawn_whole():
    x = np.arange(300.0)
    assert np.array_equal(decimated(x, np.cos(x), limit=300), np.arange(300))


def test_long_series_keep_each_columns_lowest_and_highest_point():
    # 20 columns of 50 points each; in column c the lowest y is at offset (7 c) % 50 and the
    # highest at offset (7 c + 25) % 50, by construction
    x = np.arange(1000.0)
    y = np.zeros(1000)
    low = np.array([50 * c + (7 * c) % 50 for c in range(20)])
    high = np.array([50 * c + (7 * c + 25) % 50 for c in range(20)])
    y[low], y[high] = -1.0 - np.arange(20), 1.0 + np.arange(20)
    y[3] = np.nan  # never drawn, never chosen
    kept = decimated(x, y, limit=999, columns=20)
    assert np.array_equal(kept, np.sort(np.r_[low, high]))


def test_figures_drawn_beside_are_drawn_and_their_failures_told(tmp_path):
    def good(path):
        path.write_bytes(b'png')
        return path

    def bad(path):
        raise RuntimeError('beside')

    figures = [('a.png', good), ('b.png', good), ('c.png', bad), ('d.png', bad)]
    failed = draw_figures(figures, tmp_path, beside=lambda name: name in ('b.png', 'c.png'))
    assert failed == {'c.png': 'RuntimeError: beside', 'd.png': 'RuntimeError: beside'}
    assert sorted(p.name for p in tmp_path.glob('*.png')) == ['a.png', 'b.png']
