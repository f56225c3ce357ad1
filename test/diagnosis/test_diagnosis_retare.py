"""The tare outputs re-read through the adopted model (retare._retare).

A hand-made linear balance L = A V whose corrected data carry tare outputs off by a known
±δ per orientation (as a first fit bent by an unmodelled loop leaves them): re-reading through
the fitted model must move them towards the true A⁻¹ L_tare every pass and reach it, moving the
bridge outputs by the same amounts and the loads not at all.
"""

import importlib

import numpy as np

from balance_calib.diagnosis.statistics import ZeroPointWhitening
from balance_calib.model.tm663 import tm663_terms
from balance_calib.tare.calibration_body import CorrectedData

retare_module = importlib.import_module('balance_calib.diagnosis.retare')
state_module = importlib.import_module('balance_calib.diagnosis.search_state')

OUTPUTS = ('FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV')
COMPONENTS = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')


def _campaign():
    rng = np.random.default_rng(1)
    sensitivity = np.eye(6) * 100 + rng.normal(0, 3, (6, 6))  # L = A V
    gravity_of = np.array([[0, 0, -1.0], [0, 0, 1.0]])
    times, orientation, applied = [], [], []
    for block in range(12):
        for j in range(7):  # zero point, five loads, zero point
            load = np.zeros(6) if j in (0, 6) else rng.uniform(-1, 1, 6) * (j / 5) * 50
            times.append(60.0 * len(times))
            orientation.append(block % 2)
            applied.append(load)
    times, orientation, applied = np.array(times), np.array(orientation), np.array(applied)
    gravity = gravity_of[orientation]
    tare = np.zeros_like(applied)
    tare[:, 2], tare[:, 3] = 30.0 * gravity[:, 2], 3.0 * gravity[:, 2]
    inverse = np.linalg.inv(sensitivity)
    true_tare_outputs = tare @ inverse.T
    delta = (
        np.where(orientation[:, None] == 0, 1.0, -1.0) * 0.02 * np.array([1, 2, -1, 0.5, 1, -2])
    )
    corrected = CorrectedData(
        applied + tare,
        applied @ inverse.T + true_tare_outputs + delta,
        tare,
        true_tare_outputs + delta,
    )
    whitening = ZeroPointWhitening.for_points(times, np.all(applied == 0, axis=1), orientation)
    problem = state_module._Problem(OUTPUTS, corrected, {}, whitening, COMPONENTS, times, gravity)
    return problem, gravity, np.all(applied == 0, axis=1), true_tare_outputs


def test_the_tare_outputs_move_to_the_inverse_of_the_true_model():
    problem, gravity, zero, truth = _campaign()
    loads = problem.corrected.loads.copy()
    terms = [[t.name for t in tm663_terms('linear', OUTPUTS)] for _ in COMPONENTS]
    fits = [problem.fit(k, terms[k]) for k in range(6)]
    errors = [np.abs(problem.corrected.tare_outputs_mv - truth).max()]
    residuals = [max(np.abs(f.ols.residuals).max() for f in fits)]
    for _ in range(60):
        before = problem.corrected
        fits, reread = retare_module._retare(
            problem, fits, terms, gravity, zero, COMPONENTS, OUTPUTS
        )
        assert reread
        after = problem.corrected
        np.testing.assert_array_equal(after.loads, loads)
        np.testing.assert_allclose(
            after.bridge_outputs_mv - before.bridge_outputs_mv,
            after.tare_outputs_mv - before.tare_outputs_mv,
            atol=1e-12,
        )
        errors.append(np.abs(after.tare_outputs_mv - truth).max())
        residuals.append(max(np.abs(f.ols.residuals).max() for f in fits))
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert all(b < a for a, b in zip(residuals, residuals[1:])), residuals
    assert errors[-1] < 1e-3 * errors[0], (errors[0], errors[-1])
    assert residuals[-1] < 1e-3 * residuals[0], (residuals[0], residuals[-1])


def test_correct_tare_outputs_stay_where_they_are():
    problem, gravity, zero, truth = _campaign()
    c = problem.corrected
    problem.set_corrected(
        CorrectedData(
            c.loads, c.bridge_outputs_mv - c.tare_outputs_mv + truth, c.tare_loads, truth
        )
    )
    terms = [[t.name for t in tm663_terms('linear', OUTPUTS)] for _ in COMPONENTS]
    fits = [problem.fit(k, terms[k]) for k in range(6)]
    retare_module._retare(problem, fits, terms, gravity, zero, COMPONENTS, OUTPUTS)
    np.testing.assert_allclose(problem.corrected.tare_outputs_mv, truth, atol=1e-10)
