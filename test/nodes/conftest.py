"""Fixtures of the node tests: a probe node on its own DDS domain, the memo's calibration file."""

from live_cases import MEMO
import pytest
from ros_harness import new_domain_id, Probe

from balance_calib.calibration_file import save_calibration


@pytest.fixture
def probe():
    probe = Probe(new_domain_id())
    yield probe
    probe.close()


@pytest.fixture
def calibration_file(tmp_path):
    path = tmp_path / 'calibration.yaml'
    save_calibration(path, MEMO)
    return path
