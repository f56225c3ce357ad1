"""Fixtures shared by the live calibrator's tests."""

from live_cases import MEMO
import pytest

from balance_calib.calibration_file import save_calibration


@pytest.fixture
def calibration(tmp_path):
    path = tmp_path / 'calibration.yaml'
    save_calibration(path, MEMO)
    return path
