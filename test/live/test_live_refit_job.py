"""~/refit's job hands the calibration in use to the refit's acceptance gates (gates/), so
a refit whose sensitivities moved far from it (wrong balance, a unit error) is refused in the node
too; a balance config (nothing fitted yet) is compared only with the balance's nominal
sensitivities.
"""

from pathlib import Path

from live_cases import MEMO
import pytest

from balance_calib.calibration_file import save_calibration
from balance_calib.config import CONFIG_DIR
from balance_calib.live import refit_process
from balance_calib.live.refit_process import make_refit_job, RefitSettings, run_refit_job
from balance_calib.tunnel_axes import UPRIGHT


def _job(tmp_path, calibration_file):
    bag = tmp_path / 'bag'
    bag.mkdir()
    settings = RefitSettings('lmc6522', 'cubic', UPRIGHT, 1.1, 1.0, 60.0)
    return make_refit_job([bag], tmp_path / 'reports', calibration_file, settings)


@pytest.mark.parametrize('kind', ['calibration', 'balance_config'])
def test_the_refit_process_is_given_the_active_calibration_file(tmp_path, monkeypatch, kind):
    if kind == 'calibration':
        calibration_file = tmp_path / 'calibration.yaml'
        save_calibration(calibration_file, MEMO)
    else:
        calibration_file = Path(CONFIG_DIR) / 'lmc6522.yaml'
    seen = {}

    def fake_process(
        bags, balance, out_dir, model, *, progress, timeout_s, active_calibration=None, **kwargs
    ):
        seen['active'] = active_calibration
        raise refit_process.RefitFailed('stopped by the test')

    monkeypatch.setattr(refit_process, 'run_refit_in_process', fake_process)
    reply = run_refit_job(_job(tmp_path, calibration_file), None, progress=lambda line: None)
    assert reply == 'stopped by the test'
    assert seen['active'] == (str(calibration_file) if kind == 'calibration' else None)


def test_a_balance_config_is_told_from_a_calibration_file_as_a_full_yaml_parse_would(tmp_path):
    """is_balance_config reads top-level keys without parsing the file (80 ms of Python beside the
    live stream); it must agree with the parse on every shipped config and on a written
    calibration.
    """
    import yaml

    from balance_calib.live.refit_process import is_balance_config

    calibration = tmp_path / 'calibration.yaml'
    save_calibration(calibration, MEMO)
    files = (
        sorted(CONFIG_DIR.glob('*.yaml'))
        + sorted(CONFIG_DIR.glob('models/*.yaml'))
        + [calibration]
    )
    for path in files:
        data = yaml.safe_load(path.read_text())
        assert is_balance_config(path) == (
            isinstance(data, dict) and 'matrices' in data and 'models' not in data
        ), path
    assert is_balance_config(CONFIG_DIR / 'lmc6522.yaml') and not is_balance_config(calibration)
    nested = tmp_path / 'nested.yaml'
    nested.write_text(
        'models:\n  cubic:\n    matrices: []\nnote: |\n  matrices: in a block scalar\n'
    )
    assert not is_balance_config(nested) and not is_balance_config(tmp_path / 'missing.yaml')
