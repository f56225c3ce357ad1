"""Models, fit, inverse and transforms of the engine (TM-663 §2, §3, §10)."""

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from balance_calib.accuracy.tables import format_coefficient_tables
from balance_calib.fit.gauss_newton import gauss_newton
from balance_calib.fit.least_squares import fit_model, UnexcitedTermsError
from balance_calib.model.balance_model import BalanceModel
from balance_calib.model.inverse import InverseDidNotConverge, outputs_for_loads
from balance_calib.model.terms import parse_terms, Term
from balance_calib.model.tm663 import constant_coefficient_numbers, tm663_terms
from balance_calib.tare.calibration_body import tare_loads
from balance_calib.tunnel_axes import INVERTED, parse_installation, UPRIGHT
from balance_calib.zero_points import subtract_zero_points, ZeroPointError


def test_term_lists_follow_the_memo_numbering():
    cubic = tm663_terms('cubic')
    assert [len(tm663_terms(o)) for o in ('linear', 'quadratic', 'cubic')] == [7, 28, 34]
    # eq. (13): C8 = FXV², C14 = FXV·FYV, C28 = MYV·MZV, C29 = FXV³, C34 = MZV³
    assert cubic[7].name == 'FXV^2' and cubic[13].name == 'FXV*FYV' and cubic[27].name == 'MYV*MZV'
    assert cubic[28].name == 'FXV^3' and cubic[33].name == 'MZV^3'
    # §10.1: the constants dropped for wind-on use
    assert constant_coefficient_numbers(7) == (1, 8, 15, 22, 29, 36)
    assert constant_coefficient_numbers(28) == (1, 29, 57, 85, 113, 141)
    assert constant_coefficient_numbers(34) == (1, 35, 69, 103, 137, 171)


def test_term_names_parse_the_memo_spellings():
    assert Term.parse('FXV*FXV').name == 'FXV^2'
    assert Term.parse('FXV**3').name == 'FXV^3'
    assert Term.parse('dT * |FYV|').name == 'dT*|FYV|'
    with pytest.raises(ValueError):
        Term.parse('FXV*|FYV')
    with pytest.raises(ValueError):
        parse_terms(['FXV', 'FXV^1'])


def _total_loads(config):
    gravity = np.array([config.gravity(i) for i in config.schedule.orientation])
    return config.schedule.loads + tare_loads(config.calibration_body, gravity)


@pytest.mark.parametrize('order', ['linear', 'quadratic', 'cubic'])
def test_noise_free_data_of_a_matrix_gives_that_matrix_back(balance, order):
    truth = balance.matrices[order]
    loads = _total_loads(balance)
    outputs = outputs_for_loads(truth, loads)
    fit = fit_model(
        tm663_terms(order), outputs, loads, name=order, rated_outputs=balance.rated_outputs_by_name
    )
    scale = np.abs(truth.coefficients) + 1e-3
    assert np.max(np.abs(fit.model.coefficients - truth.coefficients) / scale) < 1e-6
    assert fit.rank == len(truth.terms) and fit.unexcited_terms == ()


def test_standard_errors_match_the_scatter_of_repeated_fits(lmc6522):
    """The reported standard error of a coefficient is its real scatter over noise draws."""
    truth = lmc6522.matrices['linear']
    loads = _total_loads(lmc6522)
    clean = outputs_for_loads(truth, loads)
    rng = np.random.default_rng(3)
    estimates, errors = [], []
    for _ in range(60):
        fit = fit_model(tm663_terms('linear'), clean, loads + rng.normal(size=loads.shape) * 2.0)
        estimates.append(fit.model.coefficients)
        errors.append(fit.standard_errors)
    scatter = np.std(estimates, axis=0)
    reported = np.mean(errors, axis=0)
    assert np.allclose(reported, scatter, rtol=0.3)


def test_component_only_schedule_cannot_determine_the_interactions(lmc6522):
    """Appendix A points 1-160 load one component at a time: the cross terms are not excited."""
    loads = _total_loads(lmc6522)
    outputs = outputs_for_loads(lmc6522.matrices['cubic'], loads)
    component_only = lmc6522.schedule.point <= 160
    with pytest.raises(UnexcitedTermsError) as err:
        fit_model(
            tm663_terms('cubic'),
            outputs[component_only],
            loads[component_only],
            name='cubic',
            rated_outputs=lmc6522.rated_outputs_by_name,
        )
    assert 'FZV*MZV' in err.value.terms and 'MYV*MZV' in str(err.value)
    dropped = fit_model(
        tm663_terms('cubic'),
        outputs[component_only],
        loads[component_only],
        name='cubic',
        rated_outputs=lmc6522.rated_outputs_by_name,
        on_unexcited='drop',
    )
    assert set(dropped.unexcited_terms) == set(err.value.terms)
    for term in dropped.unexcited_terms:
        assert np.all(dropped.model.coefficients[:, dropped.model.term_index(term)] == 0.0)


def test_gauss_newton_of_eqs_20_to_28_reaches_the_least_squares_solution(lmc6522, rng):
    loads = _total_loads(lmc6522)
    outputs = (
        outputs_for_loads(lmc6522.matrices['quadratic'], loads)
        + rng.normal(size=loads.shape) * 1e-4
    )
    direct = fit_model(tm663_terms('quadratic'), outputs, loads)
    design = direct.model.design(outputs)
    n_terms = design.shape[1]

    def residual(c):
        return (loads - design @ c.reshape(6, n_terms).T).T.reshape(-1)

    jacobian = np.kron(np.eye(6), design)
    result = gauss_newton(residual, lambda c: jacobian, np.zeros(6 * n_terms))
    assert result.converged and result.iterations <= 3
    assert np.allclose(
        result.parameters.reshape(6, n_terms), direct.model.coefficients, rtol=1e-6, atol=1e-6
    )


def test_gauss_newton_fits_a_model_nonlinear_in_its_parameters():
    """Body weight W and CG x from loads W·g and x·W·g: the product makes it nonlinear."""
    rng = np.random.default_rng(5)
    gravity_z = rng.uniform(-1, 1, 40)
    observed = (
        np.concatenate([669.44 * gravity_z, -0.0122 * 669.44 * gravity_z])
        + rng.normal(size=80) * 1e-3
    )

    def model(p):
        return np.concatenate([p[0] * gravity_z, -p[1] * p[0] * gravity_z])

    def jacobian(p):
        return np.column_stack(
            [
                np.concatenate([gravity_z, -p[1] * gravity_z]),
                np.concatenate([0 * gravity_z, -p[0] * gravity_z]),
            ]
        )

    result = gauss_newton(lambda p: observed - model(p), jacobian, np.array([500.0, 0.0]))
    assert result.converged
    assert result.parameters == pytest.approx([669.44, 0.0122], rel=1e-4)


# --- §10.2: the tunnel axes, against the memo's equations written out literally ---------------


def _eqs_50_to_55(c, v):
    """TM-663 eqs. (50)-(55): tunnel loads from tunnel outputs, linear model, installation 1."""
    fxv, fyv, fzv, mxv, myv, mzv = v
    return np.array(
        [
            -(c[2] * (-fxv) + c[3] * fyv + c[4] * (-fzv) + c[5] * mxv + c[6] * myv + c[7] * mzv),
            c[9] * (-fxv) + c[10] * fyv + c[11] * (-fzv) + c[12] * mxv + c[13] * myv + c[14] * mzv,
            -(
                c[16] * (-fxv)
                + c[17] * fyv
                + c[18] * (-fzv)
                + c[19] * mxv
                + c[20] * myv
                + c[21] * mzv
            ),
            c[23] * (-fxv)
            + c[24] * fyv
            + c[25] * (-fzv)
            + c[26] * mxv
            + c[27] * myv
            + c[28] * mzv,
            c[30] * (-fxv)
            + c[31] * fyv
            + c[32] * (-fzv)
            + c[33] * mxv
            + c[34] * myv
            + c[35] * mzv,
            c[37] * (-fxv)
            + c[38] * fyv
            + c[39] * (-fzv)
            + c[40] * mxv
            + c[41] * myv
            + c[42] * mzv,
        ]
    )


def _eqs_68_to_73(c, v):
    """TM-663 eqs. (68)-(73): installation 2 (balance rolled 180°)."""
    fxv, fyv, fzv, mxv, myv, mzv = v

    def row(k):
        return (
            c[k] * (-fxv)
            + c[k + 1] * (-fyv)
            + c[k + 2] * fzv
            + c[k + 3] * mxv
            + c[k + 4] * (-myv)
            + c[k + 5] * (-mzv)
        )

    return np.array([-row(2), -row(9), row(16), row(23), -row(30), -row(37)])


def _memo_numbering(model):
    """C1..C42 as a 1-based lookup."""
    return {
        model.coefficient_number(comp, term): model.coefficient(comp, term)
        for comp in model.components
        for term in model.term_names
    }


@pytest.mark.parametrize(
    'installation, equations', [(UPRIGHT, _eqs_50_to_55), (INVERTED, _eqs_68_to_73)]
)
def test_tunnel_axes_equal_the_memos_equations(balance, installation, equations, rng):
    model = balance.matrices['linear'].without_constant()
    c = _memo_numbering(model)
    for _ in range(50):
        tunnel_outputs = rng.uniform(-1, 1, 6) * balance.rated_output_mv
        ours = installation.to_tunnel(model.loads(installation.from_tunnel(tunnel_outputs)))
        assert np.allclose(ours, equations(c, tunnel_outputs), rtol=1e-12, atol=1e-12)


def test_cubic_tunnel_transform_is_the_memos_substitution(lmc6522, rng):
    """Eq. (62): F_X̄ = -[... C4(-F_Z̄V) ... + C31(-F_Z̄V)³ ...]: substitution of §10.2.1 in eq.
    (13).
    """
    model = lmc6522.matrices['cubic'].without_constant()
    v = rng.uniform(-1, 1, 6) * lmc6522.rated_output_mv
    substituted = np.array([-v[0], v[1], -v[2], v[3], v[4], v[5]])
    expected_fx = -model.loads(substituted)[0]
    assert UPRIGHT.to_tunnel(model.loads(UPRIGHT.from_tunnel(v)))[0] == pytest.approx(
        expected_fx, rel=1e-12
    )


@given(st.lists(st.floats(-1e4, 1e4), min_size=6, max_size=6))
def test_memo_installations_are_involutions(values):
    for installation in (UPRIGHT, INVERTED):
        assert np.allclose(installation.to_tunnel(installation.to_tunnel(values)), values)
        assert np.allclose(installation.from_tunnel(installation.to_tunnel(values)), values)


def test_installation_strings():
    assert parse_installation('-FX,FY,-FZ,MX,MY,MZ').to_tunnel([1, 2, 3, 4, 5, 6]).tolist() == [
        -1,
        2,
        -3,
        4,
        5,
        6,
    ]
    assert parse_installation('FY,FX,FZ,MY,MX,MZ').from_tunnel([2, 1, 3, 5, 4, 6]).tolist() == [
        1,
        2,
        3,
        4,
        5,
        6,
    ]
    with pytest.raises(ValueError, match='forces must map to forces'):
        parse_installation('MX,FY,FZ,FX,MY,MZ')
    with pytest.raises(ValueError, match='unknown component'):
        parse_installation('FX,FY,FZ,MX,MY,LIFT')


# --- the inverse: loads -> outputs ------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6),
    st.sampled_from(['lmc6522', 'b660h']),
    st.sampled_from(['linear', 'quadratic', 'cubic']),
)
def test_inverse_of_forward_is_identity_over_the_rated_envelope(fractions, name, order):
    from balance_calib.config import load_balance_config

    config = load_balance_config(name)
    model = config.matrices[order].without_constant()
    loads = np.array(fractions) * config.capacity
    outputs = outputs_for_loads(model, loads)
    assert np.allclose(model.loads(outputs), loads, atol=1e-9 * config.capacity.max())


def test_inverse_says_clearly_where_it_does_not_converge():
    model = BalanceModel('folded', parse_terms(['FXV', 'FXV^2']), [[1.0, -1.0]], ('FX',), ('FXV',))
    with pytest.raises(InverseDidNotConverge, match='did not converge'):
        outputs_for_loads(model, [[10.0]])  # x - x² = 10 has no real solution


def test_coefficient_tables_print_in_the_memo_layout(lmc6522):
    text = format_coefficient_tables(lmc6522.matrices['cubic'])
    assert 'COEFFICIENTS OF FX' in text and 'ENV**3' in text
    first = text.splitlines()[2]
    assert first.split()[:3] == ['1', '0.4322', '512.0584']  # Table 12, FX row "1"
    linear = format_coefficient_tables(lmc6522.matrices['linear']).splitlines()
    assert linear[1].split()[:4] == ['FX', '-6.7135', '511.5005', '1.1404']  # Table 10


# --- §5(4): zero points ---------------------------------------------------------------------


def test_zero_points_remove_a_drift_linear_within_each_block():
    times = np.arange(10.0)
    orientation = np.array([2] * 5 + [4] * 5)
    zero = np.array([1, 0, 0, 0, 1, 1, 0, 0, 1, 0], bool)
    signal = np.where(zero, 0.0, 1.0)[:, None]
    drift = (0.3 + 0.05 * times)[:, None] + np.where(orientation == 4, 2.0, 0.0)[:, None]
    result = subtract_zero_points(times, signal + drift, zero, orientation)
    assert np.allclose(result.zeroed_outputs_mv[:9], signal[:9])
    # point 10 has no zero after it in its block: its zero is the one before, held (not
    # extrapolated)
    assert result.before[9] == 8 and result.after[9] == -1
    assert result.zeroed_outputs_mv[9, 0] == pytest.approx(1.0 + 0.05)


def test_a_point_without_any_zero_point_in_its_block_is_named():
    with pytest.raises(ZeroPointError, match='first: 3'):
        subtract_zero_points(
            [0, 1, 2], [[0.0], [1.0], [1.0]], [True, False, False], [2, 2, 4], [1, 2, 3]
        )
