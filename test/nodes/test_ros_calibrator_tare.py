"""balance_calibrator over real DDS: a persisted tare never outlives its installation.

The model's weight is taken as the tare with the balance upright; a node started on the same
calibration file with the balance inverted must not restore it (it reads the untared loads, the
truth, and /diagnostics says why), and an upright node again restores it.
"""

from calibrator_harness import (
    connected,
    Stamped,
    start_calibrator,
    window,
    wrench_values,
)
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from live_cases import CAPACITY, NOISE_MV, TRUTH
import numpy as np
import pytest
from ros_harness import wait_for

from balance_calib.simulation.wind_on import wind_on_outputs

pytestmark = pytest.mark.ros
WARN = b'\x01'

# What the balance carries with the model on, in balance axes (N, N·m): the weight 0.3 FS on the
# balance's F_Z with a CG a little aft and to the side (M_Y, M_X) and a slight pitch (F_X). Mounted
# upright the weight acts along +F_Z̄; rolled 180° about the sting (inverted) along -F_Z̄, and the
# offsets of the CG change sign with the balance's Y and Z axes.
UPRIGHT_LOAD = np.array([0.01, 0.0, 0.3, 0.02, 0.05, 0.0]) * CAPACITY
INVERTED_LOAD = np.array([0.01, 0.0, -0.3, 0.02, -0.05, 0.0]) * CAPACITY
# TM-663 §10.2.2, the balance mounted inverted: F_X, F_Y, M_Y and M_Z change sign, F_Z and M_X not
INVERTED_SIGNS = np.array([-1.0, -1.0, 1.0, 1.0, -1.0, -1.0])


def outputs(load_balance, n, noise=True, seed=0):
    """Raw outputs (n, 6) mV of the cubic balance carrying `load_balance`, no electrical zero."""
    return wind_on_outputs(
        TRUTH,
        np.repeat(load_balance[None], n, axis=0),
        electrical_zero_mv=0.0,
        noise_mv=NOISE_MV if noise else 0.0,
        seed=seed,
    )


def calibration_status(diagnostics, installation):
    """The latest calibration status of /diagnostics from a node of that installation."""
    for array in reversed(list(diagnostics)):
        for status in array.status:
            if (
                status.name.endswith(': calibration')
                and f'{installation} installation' in status.message
            ):
                return status, {kv.key: kv.value for kv in status.values}


def restart(probe, node, tmp_path, calibration_file, **parameters):
    probe.retire(node)
    return start_calibrator(probe, tmp_path, calibration_file, model='cubic', **parameters)


def read_one(source, wrenches, row):
    """Send `row` until a node answers (a new node is matched after a while); its wrench. Told
    apart by its stamp from any late wrench of the node before (stamps grow with source.sent).
    """
    first_ns = 10**9 + source.sent * 10**6  # Stamped's stamps: 1 kHz from 1 s

    def answered():
        source.send(row)
        return [
            m
            for m in list(wrenches)
            if m.header.stamp.sec * 10**9 + m.header.stamp.nanosec >= first_ns
        ]

    return wrench_values(wait_for(answered, 20.0, 'a wrench from the node', poll_s=0.05)[:1])[0]


def test_a_tare_taken_upright_is_not_restored_inverted_and_is_restored_upright(
    probe, tmp_path, calibration_file
):
    node = start_calibrator(
        probe, tmp_path, calibration_file, model='cubic', installation='upright'
    )
    wrenches = probe.subscribe(WrenchStamped, '/balance/wrench')
    diagnostics = probe.subscribe(DiagnosticArray, '/diagnostics')
    source = Stamped(probe)
    connected(node, source)
    wind_off = outputs(UPRIGHT_LOAD, 100)
    tare = window(probe, node, source, 'tare', wind_off)
    assert tare.success and 'saved to' in tare.message, tare.message
    full_scale = CAPACITY

    # the balance rolled 180° on the sting, the same calibration file: the tare is not applied
    node = restart(probe, node, tmp_path, calibration_file, installation='inverted')
    assert node.session.live.tare.tare_load is None
    read = read_one(source, wrenches, outputs(INVERTED_LOAD, 1, noise=False)[0])
    truth = INVERTED_SIGNS * INVERTED_LOAD  # the untared load, tunnel axes
    np.testing.assert_allclose(read / full_scale, truth / full_scale, atol=1e-6)
    status, values = wait_for(
        lambda: calibration_status(diagnostics, 'inverted'),
        10.0,
        'diagnostics of the inverted node',
    )
    assert status.level == WARN and 'NOT restored' in status.message, status.message
    why = values['tare_not_restored']
    assert 'taken in the upright installation' in why and 'now inverted' in why, why
    assert values['tare_load'] == 'none'

    # upright again: the tare is restored and the model's weight reads zero
    node = restart(probe, node, tmp_path, calibration_file, installation='upright')
    assert node.session.live.tare.tare_load is not None
    read = read_one(source, wrenches, wind_off.mean(axis=0))
    # to the second-order effect of the noise (mean f(V) against f(mean V))
    np.testing.assert_allclose(read / full_scale, 0.0, atol=1e-6)
    del diagnostics[:]  # the upright node's own, not its first life's
    status, values = wait_for(
        lambda: calibration_status(diagnostics, 'upright'), 10.0, 'diagnostics of the upright node'
    )
    assert status.level == b'\x00' and values['tare_not_restored'] == 'none', status.message
