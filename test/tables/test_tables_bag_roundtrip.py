"""A campaign recorded as a bag, exported as a table and fitted from it (direct method, TM-663
cubic terms), gives the calibration that `refit` gives from the bag, within numerical noise; the
series tare takes the place of the cubic's constant terms.
"""

import numpy as np

from balance_calib.calibrate.from_bags import RefitSettings, run_refit
from balance_calib.cli import main
from balance_calib.config import load_balance_config
from balance_calib.tables.balfit_reader import read_table
from balance_calib.tables.calibrate import calibrate_table


def test_bag_to_table_to_fit_equals_bag_to_refit(tmp_path, capsys, campaigns):
    config = load_balance_config('lmc6522')
    bag = campaigns.bag(seed=23, recipe='bag')
    refit = run_refit(
        [bag], 'lmc6522', tmp_path / 'refit', RefitSettings(diagnose=False, plots=False)
    )
    cubic = refit.calibration.models['cubic']

    table_path = tmp_path / 'campaign.csv'
    assert main(['export-table', str(bag), '--balance', 'lmc6522', '--out', str(table_path)]) == 0
    table = read_table(table_path)
    assert table.points == refit.report['points']
    result = calibrate_table(table, method='direct', terms='tm663-cubic', statistics=False)
    direct = result.fits['direct']
    # every non-constant coefficient equal to numerical noise (relative to its own size at rated
    # output)
    for component_index, component in enumerate(config.components):
        for term in direct.model.terms:
            ours = direct.model.coefficient(component, term.name)
            theirs = cubic.coefficient(component, term.name)
            size = np.prod(
                [config.rated_outputs_by_name[f.variable] ** f.power for f in term.factors]
            )
            assert abs(ours - theirs) * size <= 1e-9 * config.capacity[component_index], (
                component,
                term.name,
            )
    # the one series' tare is minus the refit's constant terms
    constant = np.array([cubic.coefficient(c, '1') for c in config.components])
    np.testing.assert_allclose(direct.tares[0], -constant, atol=1e-9 * config.capacity.max())
    # and the loads of every point agree
    outputs = table.bridge_outputs
    np.testing.assert_allclose(
        direct.model.loads(outputs) - direct.tares[0],
        cubic.loads(outputs),
        atol=1e-9 * config.capacity.max(),
    )


def test_refit_calibration_carries_the_covariance_the_live_uncertainty_needs(tmp_path, campaigns):
    from balance_calib.calibration_file import load_calibration
    from balance_calib.model.uncertainty import load_standard_uncertainty

    config = load_balance_config('lmc6522')
    bag = campaigns.bag(seed=24, recipe='bag')
    run_refit([bag], 'lmc6522', tmp_path / 'refit', RefitSettings(diagnose=False, plots=False))
    calibration = load_calibration(tmp_path / 'refit' / 'calibration.yaml')
    outputs = np.diag(config.rated_output_mv) * 0.5  # one bridge at half its rated output
    u = load_standard_uncertainty(calibration, outputs, model='cubic')
    sigma = np.asarray(calibration.model('cubic').metadata['uncertainty']['residual_sigma'])
    assert np.all(np.isfinite(u)) and np.all(u >= sigma) and np.all(u < 2 * sigma)
    # six bridges at once at 80 %: off the schedule's support, the uncertainty grows
    assert np.all(
        load_standard_uncertainty(
            calibration, 0.8 * config.rated_output_mv[None, :], model='cubic'
        )[0]
        > u.max(axis=0)
    )
