"""The calibration engine against the memo's own numbers (TM-663 Tables 4-9, 17, Appendix A/B)."""

import numpy as np
import pytest

from balance_calib.accuracy.sigma import sigma_pct_fs
from balance_calib.fit.least_squares import fit_model
from balance_calib.model.tm663 import tm663_terms
from balance_calib.reduction import reduce_points, retare_with_model
from balance_calib.tare.calibration_body import body_loads_from_rotation, tare_loads


@pytest.mark.parametrize(
    'name, weight, my', [('lmc6522', 669.4, -8.163), ('b660h', 681.6, -4.635)]
)
def test_body_weight_from_rotation_outputs_reproduces_tables_5_and_8(name, weight, my, request):
    """Eqs. (29)-(31) with the linear matrix (Table 10/14) and the output change of Table 4/7."""
    config = request.getfixturevalue(name.replace('6522', '6522'))
    delta = config.raw['calibration_body']['rotation_outputs_mv']['difference']
    loads = body_loads_from_rotation(config.matrices['linear'], delta)
    assert loads[2] == pytest.approx(weight, rel=1e-3)  # F_Z(CB), eq. (29)
    assert loads[4] == pytest.approx(my, rel=1e-3)  # M_Y(CB), eq. (31)
    assert abs(loads[3]) < 0.1  # M_X(CB) small: CG on the axis


def test_body_weight_uses_the_difference_of_the_two_printed_rows(lmc6522):
    rows = lmc6522.raw['calibration_body']['rotation_outputs_mv']
    assert np.allclose(np.subtract(rows['fz_down'], rows['fz_up']), rows['difference'], atol=2e-5)


@pytest.mark.parametrize('name', ['lmc6522', 'b660h'])
def test_tare_loads_reproduce_tables_9_and_13(name, request):
    config = request.getfixturevalue(name)
    table = config.raw['calibration_body']['memo_tare_table']
    w, m, d, dm = (
        table['weight_n'],
        table['moment_nm'],
        table['diagonal_n'],
        table['diagonal_moment_nm'],
    )
    expected = {
        1: [0, w, 0, 0, 0, m],
        2: [0, 0, w, 0, -m, 0],
        3: [0, -w, 0, 0, 0, -m],
        4: [0, 0, -w, 0, m, 0],
        5: [0, d, d, 0, -dm, dm],
        6: [0, d, -d, 0, dm, dm],
        7: [0, -d, d, 0, -dm, -dm],
        8: [0, -d, -d, 0, dm, -dm],
    }
    for orientation, row in expected.items():
        loads = tare_loads(config.calibration_body, config.gravity(orientation))
        # the memo rounds via kgf (48.30 kgf for W/sqrt(2)): 0.03 N of 473 N
        assert np.allclose(loads[:3], row[:3], atol=0.05), (orientation, loads, row)
        assert np.allclose(loads[3:], row[3:], atol=0.005), (orientation, loads, row)


def test_schedules_have_the_executed_points_of_appendices_a_and_b(lmc6522, b660h):
    assert len(lmc6522.schedule) == 328 and len(b660h.schedule) == 332
    # spot values as printed: LMC6522 point 187 (F_X 50, F_Y 495, F_Z 495, M_X 10, M_Y 35, M_Z -35
    # kgf/kgfm)
    row = lmc6522.schedule.loads[list(lmc6522.schedule.point).index(187)]
    assert np.allclose(row / 9.80665, [50, 495, 495, 10, 35, -35])
    assert lmc6522.schedule.orientation[list(lmc6522.schedule.point).index(187)] == 5


def test_matrices_hold_the_printed_coefficients(lmc6522, b660h):
    assert lmc6522.matrices['linear'].coefficient('FX', 'FZV') == 39.3786  # Table 10, C4
    assert lmc6522.matrices['cubic'].coefficient('FZ', 'FZV^3') == -8.4515  # Table 12
    assert lmc6522.matrices['quadratic'].coefficient('FX', 'FZV*MZV') == -91.4111  # Table 11
    assert b660h.matrices['cubic'].coefficient('MZ', 'MZV^3') == 1.1045  # Table 16 ENV**3
    assert b660h.matrices['linear'].coefficient_number('MZ', 'MZV') == 42
    assert b660h.matrices['cubic'].coefficient_number('MZ', 'MZV^3') == 204


def _reduced_campaign(campaigns, name, config, seed):
    points = campaigns.points(name, seed=seed)  # Table 17's cubic row as the noise
    reduction = reduce_points(points, config, estimate_body_weight=False)
    first = fit_model(
        tm663_terms('cubic'),
        reduction.corrected.bridge_outputs_mv,
        reduction.corrected.loads,
        rated_outputs=config.rated_outputs_by_name,
    )
    return retare_with_model(reduction, first.model)


@pytest.mark.parametrize('name', ['lmc6522', 'b660h'])
def test_linear_fit_sigma_matches_table17_and_nonlinear_fits_reach_the_noise_floor(
    name, request, campaigns
):
    """Cubic matrix as truth, Appendix schedule in SI, Table 9/13 tare, Table 17 cubic row as
    noise.
    """
    config = request.getfixturevalue(name)
    reduction = _reduced_campaign(campaigns, name, config, seed=7)
    data = reduction.corrected
    noise = np.array([config.table17_sigma_pct_fs['cubic'][c] for c in config.components])
    sigma = {}
    for order in ('linear', 'quadratic', 'cubic'):
        fit = fit_model(
            tm663_terms(order),
            data.bridge_outputs_mv,
            data.loads,
            name=order,
            rated_outputs=config.rated_outputs_by_name,
        )
        sigma[order] = sigma_pct_fs(fit.residuals, config.capacity)
    table = np.array([config.table17_sigma_pct_fs['linear'][c] for c in config.components])
    assert np.all(np.abs(sigma['linear'] - table) <= 0.02), (sigma['linear'], table)
    n = len(data.loads)
    # The simulated noise is set so that it scatters as Table 17's cubic row after the zero points;
    # a fit of p terms per component leaves sqrt((N - p) / N) of it (eq. (44) divides by N).
    # The quadratic model also lacks the cubic truth's cubes (<= 0.016 % FS noise-free), hence
    # 1.25.
    for order, p, upper in (('quadratic', 28, 1.25), ('cubic', 34, 1.12)):
        floor = noise * np.sqrt((n - p) / n)
        assert np.all(sigma[order] <= upper * floor), (order, sigma[order], floor)
        assert np.all(sigma[order] >= 0.8 * floor), (order, sigma[order], floor)
