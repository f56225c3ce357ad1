"""Residual plots of a diagnosis (TM-663 Figs. 4-9 style) and per-effect plots, as PNG files."""

from matplotlib.image import imread
import numpy as np
import pytest

from balance_calib.diagnosis import diagnose
from balance_calib.diagnosis.plots import CLIP_PCT_FS, plot_diagnosis, plot_residuals
from balance_calib.simulation.diagnosis_rates import (
    calibrated_parameter,
    injected_effects,
    simulate_reduction,
)


@pytest.fixture(scope='module')
def hysteresis_diagnosis(lmc6522):
    effects, _ = injected_effects('hysteresis', calibrated_parameter('lmc6522', 'hysteresis', 6.0))
    return diagnose(simulate_reduction(lmc6522, effects, seed=2), lmc6522)


def test_plot_diagnosis_writes_before_after_and_one_figure_per_effect(
    hysteresis_diagnosis, tmp_path
):
    paths = plot_diagnosis(hysteresis_diagnosis, tmp_path)
    assert [p.name for p in paths] == [
        'residuals_cubic.png',
        'residuals_adopted.png',
        'effect_hysteresis.png',
    ]
    for path in paths:
        image = imread(path)
        assert image.shape[0] > 300 and image.shape[1] > 500
        assert np.std(image[..., :3]) > 0.05  # something is drawn


def test_residual_plot_has_six_panels_clipped_at_half_a_percent(
    hysteresis_diagnosis, tmp_path, monkeypatch
):
    """Points beyond ±0.5 % FS (the memo's axis) are drawn on the edge, not dropped."""
    import balance_calib.diagnosis.plots as plots

    figures = []
    original = plots._save
    monkeypatch.setattr(
        plots, '_save', lambda figure, path: (figures.append(figure), original(figure, path))[1]
    )
    plot_residuals(hysteresis_diagnosis, tmp_path / 'before.png', which='before')
    axes = figures[0].axes
    assert len(axes) == 6 and [a.get_title().split(':')[0] for a in axes] == [
        'FX',
        'FY',
        'FZ',
        'MX',
        'MY',
        'MZ',
    ]
    assert axes[0].get_ylim() == (-CLIP_PCT_FS, CLIP_PCT_FS)
    beyond = np.abs(hysteresis_diagnosis.residuals_pct_fs('before')[:, 0]) > CLIP_PCT_FS
    assert beyond.any(), 'the fixture should have points beyond the axis'
    drawn = sum(len(line.get_xdata()) for line in axes[0].get_lines()[1:])  # [0] is the zero line
    assert drawn == hysteresis_diagnosis.points
