"""balance_calibrator, as its own process over real DDS, on a 3-component calibration that `fit
--axes FZ,MX,MY` wrote from a small laboratory table: each raw sample gives the three components
the cell's own linear response says (hand-computed), the other three 0 with their uncertainty NaN,
and /diagnostics names the absent components; a calibration of 8 bridge outputs stops it with one
line.
"""

import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
import numpy as np
from partial_cells import CAPACITY, fit_cell, raw_samples, SIGMA_LOAD, SLOTS
import pytest
from ros_harness import new_domain_id, NodeProcess, Probe, RELIABLE, six, wait_for

from balance_calib.nodes._messages import set_wrench

pytestmark = pytest.mark.ros
ABSENT_SLOTS = [0, 1, 5]
UPRIGHT_SIGNS = np.array([-1.0, 1.0, -1.0, 1.0, 1.0, 1.0])  # TM-663 §10.2.1, written out


def _publish(publisher, values, sec: int, nanosec: int = 0) -> None:
    msg = WrenchStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    msg.header.frame_id = 'cell-3'
    set_wrench(msg.wrench, values)
    publisher.publish(msg)


def _calibration_status(arrays):
    for array in reversed(arrays):
        for status in array.status:
            if status.name.endswith(': calibration'):
                return status, {kv.key: kv.value for kv in status.values}
    return None


def test_a_three_component_calibration_runs_in_the_node(tmp_path):
    calibration_file = fit_cell(tmp_path)
    rng = np.random.default_rng(21)
    loads = rng.uniform(-0.9, 0.9, (20, 3)) * CAPACITY
    samples = raw_samples(rng, loads)
    expected = np.zeros((20, 6))
    expected[:, SLOTS] = loads  # K⁻¹ · (K · L): the applied loads themselves
    expected *= UPRIGHT_SIGNS

    probe = Probe(new_domain_id())
    node = NodeProcess(
        'balance_calibrator',
        probe.domain_id,
        tmp_path / 'logs',
        {'calibration_file': str(calibration_file), 'installation': 'upright'},
    )
    try:
        wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
        uncertainties = probe.subscribe(WrenchStamped, '/balance/wrench_uncertainty')
        diagnostics = probe.subscribe(DiagnosticArray, '/diagnostics')
        raw = probe.node.create_publisher(WrenchStamped, '/balance/raw', RELIABLE)
        readers = {s.topic_name: s for s in probe.node.subscriptions}
        wait_for(
            lambda: (
                raw.get_subscription_count() >= 1
                and readers['/balance/wrench'].get_publisher_count() >= 1
                and readers['/balance/wrench_uncertainty'].get_publisher_count() >= 1
            ),
            60.0,
            'the calibrator to connect',
        )
        # the node computes the uncertainty once it has seen its reader: warm-up samples until then

        def uncertainty_flows():
            _publish(raw, samples[0], sec=1, nanosec=len(wrenches))
            time.sleep(0.05)
            return len(uncertainties) > 0

        wait_for(uncertainty_flows, 60.0, 'the first /balance/wrench_uncertainty')
        for i, values in enumerate(samples):
            _publish(raw, values, sec=100 + i)

        def by_stamp(messages):
            found = {m.header.stamp.sec - 100: m for m in messages if m.header.stamp.sec >= 100}
            return found if len(found) == len(samples) else None

        got_wrench = wait_for(lambda: by_stamp(wrenches), 60.0, f'{len(samples)} wrenches')
        got_u = wait_for(lambda: by_stamp(uncertainties), 60.0, f'{len(samples)} uncertainties')
        wrench = np.array([six(got_wrench[i]) for i in range(len(samples))])
        uncertainty = np.array([six(got_u[i]) for i in range(len(samples))])

        assert np.all(wrench[:, ABSENT_SLOTS] == 0.0)
        error = np.abs(wrench[:, SLOTS] - expected[:, SLOTS])
        assert np.all(error < 5 * SIGMA_LOAD), error / SIGMA_LOAD
        assert np.all(np.isnan(uncertainty[:, ABSENT_SLOTS]))
        ratio = uncertainty[:, SLOTS] / SIGMA_LOAD  # the output noise carried to the loads
        assert np.all((ratio > 0.6) & (ratio < 1.4)), ratio

        status, values = wait_for(
            lambda: _calibration_status(diagnostics),
            30.0,
            'the calibration status on /diagnostics',
        )
        assert values['components'] == 'FZ, MX, MY'
        assert values['absent_components'] == 'FX, FY, MZ'
        assert 'FX, FY, MZ absent (published as 0, uncertainty NaN)' in status.message
        assert status.level == b'\x00'
    finally:
        node.stop()
        probe.close()
    assert 'FX, FY, MZ absent from the calibration' in node.output()


def test_a_calibration_of_eight_outputs_stops_the_node_with_one_line(tmp_path):
    from live_cases import eight_output_calibration

    from balance_calib.calibration_file import save_calibration

    path = tmp_path / 'sensor8.yaml'
    save_calibration(path, eight_output_calibration())
    node = NodeProcess(
        'balance_calibrator', new_domain_id(), tmp_path / 'logs', {'calibration_file': str(path)}
    )
    try:
        assert node.wait(30.0) == 1
        errors = [line for line in node.output().splitlines() if '[ERROR]' in line]
        assert len(errors) == 1, node.output()
        said = f'cannot start: {path}: bridge outputs E1, E2, E3, E4, E5, E6, E7, E8: '
        assert said in errors[0], errors[0]
        assert errors[0].count(str(path)) == 1 and 'invalid parameter' not in errors[0]
    finally:
        node.stop()
