"""balance_calibrator over real DDS says when the tunnel leaves the calibration: /diagnostics'
`outside_support_share` (the share of the last period's samples outside the active calibration's
support, coverage/support.py) above zero and WARN while the loads are beyond the support, zero and
OK again inside.
"""

from calibrator_harness import (
    connected,
    Stamped,
    start_calibrator,
)
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
import numpy as np
import pytest
from ros_harness import wait_for
from support_cases import (
    loads_with_some_outside,
    outputs_of,
    supported_calibration,
)

from balance_calib.calibration_file import save_calibration

pytestmark = pytest.mark.ros
OK, WARN = b'\x00', b'\x01'


def test_diagnostics_warn_with_the_share_outside_the_support_and_are_ok_inside(probe, tmp_path):
    calibration = supported_calibration()
    path = tmp_path / 'calibration.yaml'
    save_calibration(path, calibration)  # the support travels in calibration.yaml
    node = start_calibrator(probe, tmp_path, path, model='cubic')
    probe.subscribe(WrenchStamped, '/balance/wrench')
    diagnostics = probe.subscribe(DiagnosticArray, '/diagnostics')
    source = Stamped(probe)
    connected(node, source)
    outside_rows = np.arange(0, 200, 2)  # half the samples with F_Z at 50 % of capacity
    beyond = outputs_of(calibration, loads_with_some_outside(200, outside_rows))
    inside = outputs_of(calibration, loads_with_some_outside(1, []))[0]

    def calibration_status(level, wanted):
        for array in reversed(diagnostics[-3:]):
            for status in array.status:
                values = {kv.key: kv.value for kv in status.values}
                if 'outside_support_share' in values and status.level == level:
                    share = values['outside_support_share']
                    if wanted(share):
                        return status, values
        return None

    sent = 0

    def send_beyond():
        nonlocal sent
        source.send(beyond[sent % len(beyond)])
        sent += 1

    timer = probe.node.create_timer(1.0 / 200.0, send_beyond)
    status, values = wait_for(
        lambda: calibration_status(WARN, lambda share: float(share) > 0.3),
        15.0,
        'a WARN with the share outside the support',
    )
    timer.cancel()
    # every second sample beyond: the share of a 0.2 s period is about one half
    assert 0.3 < float(values['outside_support_share']) < 0.7
    assert values['outside_support_components'] == 'FZ'
    assert "outside the calibration's support (FZ)" in status.message
    timer = probe.node.create_timer(1.0 / 200.0, lambda: source.send(inside))
    status, values = wait_for(
        lambda: calibration_status(OK, lambda share: share == '0.0000'),
        15.0,
        'OK with nothing outside the support',
    )
    timer.cancel()
    assert 'support' not in status.message
