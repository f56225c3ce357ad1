"""The refit pipeline and `balance-calib refit` on real MCAP bags written from simulated
campaigns.
"""

import json
from pathlib import Path
import subprocess

import numpy as np
import pytest

from balance_calib.calibrate.from_bags import RefitSettings, run_refit
from balance_calib.calibration_file import load_calibration
from balance_calib.config import load_balance_config
from balance_calib.model.inverse import outputs_for_loads
from balance_calib.refit.pipeline import RefitError

REPORT_KEYS = {
    'balance',
    'points',
    'base_model',
    'calibration_body',
    'sigma_pct_fs',
    'sigma_pct_fs_crossval',
    'effects',
    'adopted',
}


@pytest.fixture(scope='module')
def campaign_bag(campaigns):
    return campaigns.bag(seed=11, recipe='bag'), campaigns.campaign(seed=11, recipe='bag')


def _run_cli(*args):
    return subprocess.run(
        ['balance-calib', *map(str, args)], capture_output=True, text=True, timeout=300
    )


def test_refit_command_writes_the_promised_files(campaign_bag, tmp_path):
    bag, campaign = campaign_bag
    out = tmp_path / 'out'
    done = _run_cli('refit', bag, '--balance', 'lmc6522', '--out', out, '--no-diagnosis')
    assert done.returncode == 0, done.stderr
    assert (out / 'calibration.yaml').exists() and (out / 'report.md').exists()
    assert sorted(p.name for p in out.glob('*.png')) == [
        'residuals_cubic.png',
        'residuals_linear.png',
        'residuals_quadratic.png',
    ]
    report = json.loads((out / 'report.json').read_text())
    assert REPORT_KEYS <= set(report)
    assert (
        report['balance'] == 'LMC6522'
        and report['points'] == 328
        and report['base_model'] == 'cubic'
    )
    assert set(report['sigma_pct_fs']['before']) == {'FX', 'FY', 'FZ', 'MX', 'MY', 'MZ'}
    assert report['calibration_body']['source'] == 'estimated'
    assert report['calibration_body']['weight_N'] == pytest.approx(669.44, rel=2e-3)
    assert report['effects'] == [] and report['adopted'] is False
    # the cubic fit of a cubic truth reaches the noise of the memo's Table 17 (cubic row)
    table = report['table17_memo']['cubic']
    for component, sigma in report['sigma_pct_fs']['before'].items():
        assert sigma <= 1.15 * table[component], component
    calibration = load_calibration(out / 'calibration.yaml')
    assert calibration.adopted == 'cubic' and set(calibration.models) == {
        'linear',
        'quadratic',
        'cubic',
    }
    assert 'COEFFICIENTS OF FX' in (out / 'report.md').read_text()


def test_refit_recovers_the_truth_matrix_within_its_standard_errors(campaign_bag, tmp_path):
    bag, campaign = campaign_bag
    config = load_balance_config('lmc6522')
    result = run_refit(
        [bag], 'lmc6522', tmp_path / 'out', RefitSettings(diagnose=False, plots=False)
    )
    fitted = result.calibration.model('cubic').without_constant()
    truth = config.matrices['cubic'].without_constant()
    # compare what matters: the loads both give inside the calibrated envelope (the schedule's
    # loads, with the body weight); far outside it no calibration can be trusted
    outputs = outputs_for_loads(truth, campaign.true_loads)
    error_pct = (fitted.loads(outputs) - truth.loads(outputs)) / config.capacity * 100
    assert np.all(np.sqrt(np.mean(error_pct**2, axis=0)) < 0.05)


def test_bad_inputs_fail_with_one_line_naming_the_problem_and_write_nothing(
    campaign_bag, tmp_path
):
    bag, _ = campaign_bag
    out = tmp_path / 'out'
    missing = _run_cli('refit', tmp_path / 'nope', '--balance', 'lmc6522', '--out', out)
    assert (
        missing.returncode == 2
        and 'nope' in missing.stderr
        and len(missing.stderr.strip().splitlines()) == 1
    )
    assert not out.exists() or not any(out.iterdir())
    truncated = tmp_path / 'truncated.mcap'
    data = next(Path(bag).glob('*.mcap')).read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    cut = _run_cli('refit', truncated, '--balance', 'lmc6522', '--out', out)
    assert cut.returncode == 2 and 'truncated.mcap' in cut.stderr
    assert not out.exists() or not any(out.iterdir())
    wrong_balance = _run_cli('refit', bag, '--balance', tmp_path / 'none.yaml', '--out', out)
    assert wrong_balance.returncode == 2 and 'none.yaml' in wrong_balance.stderr


def test_a_schedule_that_cannot_determine_the_cubic_terms_is_refused_by_name(tmp_path, campaigns):
    bag = campaigns.bag(points=slice(0, 160))  # the single-component points alone
    with pytest.raises(
        RefitError,
        match=r'does not excite \d+ term\(s\) of the (quadratic|cubic) model: .*MYV\*MZV',
    ):
        run_refit([bag], 'lmc6522', tmp_path / 'out', RefitSettings(diagnose=False))
    assert not (tmp_path / 'out' / 'calibration.yaml').exists()


def test_a_campaign_split_over_two_bags_refits_as_one(tmp_path, campaigns):
    first = campaigns.bag('b660h', seed=4, points=slice(0, 200))
    second = campaigns.bag('b660h', seed=4, points=slice(200, None))
    bare = next(second.glob('*.mcap'))
    result = run_refit(
        [first, bare], 'b660h', tmp_path / 'out', RefitSettings(diagnose=False, plots=False)
    )
    assert result.report['points'] == 332
    assert max(result.report['sigma_pct_fs']['before'].values()) < 0.07
