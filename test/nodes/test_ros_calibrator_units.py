"""Bridge outputs recorded ratiometrically (mV/V, µV/V) at the edge: balance_calibrator's
input_units and excitation_v turn them into the mV the calibration is written in; a ratiometric
unit without an excitation is refused at start-up and at runtime, naming both parameters.
"""

from calibrator_harness import (
    connected,
    RawSource,
    SAMPLE_MV,
    start_calibrator,
    wrench_values,
)
from geometry_msgs.msg import WrenchStamped
from live_cases import MEMO
import numpy as np
import pytest
from rclpy.parameter import Parameter
from ros_harness import wait_for

from balance_calib.calibration_file import ConfigError
from balance_calib.live.calibrator_core import compute_wrench
from balance_calib.live.parameters import input_scale_mv
from balance_calib.model.active_calibration import activate


def test_input_scale_is_the_excitation_for_mv_per_v_and_a_thousandth_of_it_for_microv_per_v():
    assert input_scale_mv('mV', 0.0) == 1.0
    assert input_scale_mv('mV/V', 5.0) == pytest.approx(5.0, rel=1e-15)  # 1 mV/V at 5 V is 5 mV
    # 1 µV/V at 10 V is 0.01 mV
    assert input_scale_mv('microV/V', 10.0) == pytest.approx(0.01, rel=1e-15)
    for excitation in (0.0, -1.0, float('nan')):
        with pytest.raises(ValueError, match='input_units = mV/V needs excitation_v > 0'):
            input_scale_mv('mV/V', excitation)


@pytest.mark.ros
def test_mv_per_v_input_at_5_v_reads_as_the_same_outputs_in_mv(probe, tmp_path, calibration_file):  # noqa: F811
    node = start_calibrator(
        probe, tmp_path, calibration_file, input_units='mV/V', excitation_v=5.0
    )
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    source = RawSource(probe)
    connected(node, source)
    for _ in range(5):
        source.send(tuple(v / 5.0 for v in SAMPLE_MV))  # what a 5 V bridge reads, in mV/V
    wait_for(lambda: len(wrenches) >= 5, 10.0, 'wrenches of the mV/V samples')
    expected = compute_wrench(activate(MEMO), np.array([SAMPLE_MV])).wrench_tunnel[0]
    np.testing.assert_allclose(
        wrench_values(wrenches), np.tile(expected, (5, 1)), rtol=1e-12, atol=1e-9
    )
    # a ratiometric unit with the excitation taken away is refused; the stream keeps its setting
    result = node.set_parameters([Parameter('excitation_v', value=0.0)])[0]
    assert not result.successful and 'excitation_v > 0' in result.reason
    assert node.get_parameter('excitation_v').value == 5.0


@pytest.mark.ros
def test_a_ratiometric_unit_without_excitation_cannot_start(probe, tmp_path, calibration_file):  # noqa: F811
    with pytest.raises(ConfigError, match='input_units = microV/V needs excitation_v > 0'):
        start_calibrator(probe, tmp_path, calibration_file, input_units='microV/V')
    with pytest.raises(ConfigError, match='input_units must be one of mV, mV/V, microV/V'):
        start_calibrator(probe, tmp_path, calibration_file, input_units='V')
