"""Hysteresis and sign asymmetry told apart by the schedule's own structure:
the direction contrast (falling - rising at equal load) of a loop written from its physics is far
beyond two points' repeatability, that of a sign asymmetry (a sensitivity step at zero, a
curvature on negative loads) and of a clean campaign is not; the refit draws both contrasts.

Measured (LMC6522, M_Y, 1x the floor, seeds 0-1): direction ratio mean(c²)/(2 s²) 8.5-13 for
Preisach and Bouc-Wen loops, 1.3-2.1 for both sign shapes and for clean campaigns. The sign
contrast does not separate them on this schedule (7-10 for loops, 15-21 for sign shapes, 1.7-1.9
clean): a loop keyed to the strain is traversed around the tare's output, not around zero load.
"""

import diagnosis_physics as physics
import numpy as np
from PIL import Image
import pytest

from balance_calib.config import load_balance_config
from balance_calib.diagnosis import diagnose
from balance_calib.diagnosis.contrasts import schedule_contrasts
from balance_calib.diagnosis.plots import contrast_figures
from balance_calib.simulation.diagnosis_rates import simulate_reduction

BALANCE, COMPONENT = 'lmc6522', 'MY'


def _diagnosis(shape, seed):
    config = load_balance_config(BALANCE)
    effects = [] if shape == 'clean' else [physics.scaled(BALANCE, shape, COMPONENT)]
    reduction, scatter = simulate_reduction(
        config, effects, seed=seed, samples_per_point=8, with_scatter=True
    )
    return diagnose(reduction, config, **scatter)


@pytest.mark.parametrize(
    'shape, loop',
    [
        ('preisach', True),
        ('bouc_wen', True),
        ('sign_step', False),
        ('negative_curvature', False),
        ('clean', False),
    ],
)
def test_the_direction_contrast_sees_a_loop_and_not_a_sign_asymmetry(shape, loop):
    diagnosis = _diagnosis(shape, seed=0)
    direction, sign = schedule_contrasts(diagnosis)[COMPONENT]
    assert direction.kind == 'direction' and sign.kind == 'sign'
    assert direction.count >= 20 and sign.count >= 10  # the schedule's pairs on M_Y
    if loop:
        assert direction.ratio > 5.0 and direction.p_value < 1e-10, direction.ratio
    else:
        assert direction.ratio < 3.0, direction.ratio
    # every pair is what it says: equal loads, opposite histories / opposite signs
    labels = list(diagnosis.point_labels)
    applied = diagnosis.corrected.loads - diagnosis.corrected.tare_loads
    k = diagnosis.components.index(COMPONENT)
    for falling, rising in direction.pairs:
        f, r = labels.index(falling), labels.index(rising)
        assert np.allclose(applied[f], applied[r], atol=1e-3 * diagnosis.capacity.max())
        assert diagnosis.load_direction[f, k] == -1 and diagnosis.load_direction[r, k] == 1
    for plus, minus in sign.pairs:
        p, m = labels.index(plus), labels.index(minus)
        assert applied[p, k] > 0 > applied[m, k]
        assert applied[p, k] == pytest.approx(-applied[m, k], rel=1e-3)


def test_the_contrast_figure_is_two_panels_wide(tmp_path):
    paths = contrast_figures(_diagnosis('preisach', seed=1), tmp_path)
    assert [p.name for p in paths] == ['contrasts.png']
    width, height = Image.open(paths[0]).size
    assert 600 <= width <= 1100 and 400 <= height <= 1300, (width, height)
    assert contrast_figures(None, tmp_path) == []
