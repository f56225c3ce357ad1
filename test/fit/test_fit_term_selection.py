"""Per-term statistics (VIF, significance, PRESS without the term) against brute force, and the
iterative model's Newton inverse: exact on its own outputs, a clear error where it cannot converge.
"""

import numpy as np
import pytest

from balance_calib.fit.crossval import press_residuals
from balance_calib.fit.term_selection import term_statistics
from balance_calib.model.inverse import InverseDidNotConverge
from balance_calib.model.r091 import IterativeModel, r091_terms
from balance_calib.tables import synthetic as sy


def test_vif_and_press_per_term_equal_their_definitions_by_refitting():
    rng = np.random.default_rng(5)
    n = 60
    x = rng.normal(size=(n, 3))
    x[:, 2] = 0.9 * x[:, 0] + 0.3 * rng.normal(size=n)  # a nearly collinear column
    design = np.column_stack([x, np.ones(n)])  # last column: a nuisance (a tare)
    targets = np.column_stack([design @ [1.0, -2.0, 0.5, 0.3], design @ [0.0, 1.0, 0.0, -1.0]])
    targets += rng.normal(0, 0.1, targets.shape)
    covariance = np.linalg.inv(design.T @ design)
    coefficients = covariance @ design.T @ targets
    stats = term_statistics(
        design, targets, coefficients, covariance, 3, ['a', 'b', 'c'], ['y1', 'y2']
    )
    press_full = (press_residuals(design, targets - design @ coefficients) ** 2).sum(axis=0)
    for j in range(3):
        others = np.delete(design, j, axis=1)
        fitted = others @ np.linalg.lstsq(others, targets, rcond=None)[0]
        press_without = (press_residuals(others, targets - fitted) ** 2).sum(axis=0)
        np.testing.assert_allclose(stats.press_ratio[j], press_without / press_full, rtol=1e-9)
        column = design[:, j]
        explained = others @ np.linalg.lstsq(others, column, rcond=None)[0]
        r2_uncentred = 1 - np.sum((column - explained) ** 2) / np.sum(column**2)
        np.testing.assert_allclose(stats.vif[j], 1 / (1 - r2_uncentred), rtol=1e-9)
    assert stats.vif[2] > 5 and stats.vif[1] < 2
    # b matters for y1; a not for y2
    assert stats.p_value[1, 0] < 1e-6 and stats.p_value[0, 1] > 1e-3


def test_newton_inverse_recovers_loads_and_names_the_sample_it_cannot_invert():
    rng = np.random.default_rng(8)
    truth = sy.iterative_truth(rng)
    loads = sy.six_at_once(rng, 500, fraction=1.0)
    np.testing.assert_allclose(
        truth.loads(truth.outputs(loads)), loads, atol=1e-8 * sy.capacity_si().max()
    )
    # a balance whose F_X output folds back (V = F - F³/3 has no solution above V = 2/3)
    folding = IterativeModel(
        'folding', r091_terms(('F',)), np.array([[1.0, 0, 0, 0, -1 / 3, 0]]), ('F',), ('V',)
    )
    assert folding.term_names[4] == 'F^3'
    outputs = np.array([[0.1], [0.5], [0.9]])
    with pytest.raises(InverseDidNotConverge, match=r'sample 2 \(outputs \[0\.9\]\)'):
        folding.loads(outputs)
    np.testing.assert_allclose(
        folding.outputs(folding.loads(outputs[:2])), outputs[:2], atol=1e-12
    )


@pytest.mark.slow  # ~17 s on 2 cores: two iterative fits of 21 series, one selecting terms
def test_select_drops_the_terms_the_truth_lacks_and_validates_no_worse():
    from dataclasses import replace

    from balance_calib.tables.calibrate import calibrate_table

    rng = np.random.default_rng(3)
    truth = sy.iterative_truth(rng)
    absent = rng.random(len(truth.terms)) < 0.5
    absent[
        [j for j, t in enumerate(truth.terms) if t.degree == 1 and not t.factors[0].absolute]
    ] = False
    coefficients = np.array(truth.coefficients)
    coefficients[:, absent] = 0.0
    truth = replace(truth, coefficients=coefficients)
    calibration, validation = sy.support_schedule(rng, 21, 100), sy.support_schedule(rng, 15, 200)
    tares = sy.tares_for(rng, np.unique(calibration.series))
    tables = [
        sy.make_table(*sy.iterative_campaign(rng, truth, s, tares, 0.0006), s.series)
        for s in (calibration, validation)
    ]
    full, selected = (
        calibrate_table(
            tables[0], method='iterative', validation=tables[1], select=select, statistics=False
        ).report
        for select in (False, True)
    )
    removed = set(selected['term_selection']['iterative']['removed'])
    lacking = {truth.terms[j].name for j in np.flatnonzero(absent)}
    assert len(removed) >= 0.8 * len(lacking) and len(removed - lacking) <= 2
    assert len(selected['terms']) == len(truth.terms) - len(removed)
    for load in sy.LOADS:
        assert (
            selected['sigma_pct_capacity']['validation'][load]
            <= 1.01 * full['sigma_pct_capacity']['validation'][load]
        )
