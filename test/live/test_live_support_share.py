"""balance_calibrator's /diagnostics says when the tunnel leaves the calibration: the share of a
period's samples outside the active calibration's support (the definition `coverage` uses,
coverage/support.py), `outside_support_share`, WARN while it is not zero.

The calibration: the memo's cubic model with a covariance (live_cases) and a support whose ranges
are set by hand, ±30 % of capacity on every component and a leverage bound no load reaches, so
that a sample is outside exactly when one of its loads is beyond 30 % + 2 % FS.
"""

from live_cases import calibration_with_covariance
import numpy as np
import pytest
from serialized_messages import serialized
from support_cases import (
    loads_with_some_outside,
    outputs_of,
    supported_calibration,
)

from balance_calib.live.diagnostics_status import OK, WARN
from balance_calib.live.raw_codec import decode_wrenches, WrenchEncoder
from balance_calib.live.stream import LiveCalibrator
from balance_calib.live.support_share import SupportSampler
from balance_calib.model.active_calibration import activate
from balance_calib.units import COMPONENTS


def decode_rows(kept):
    """A stand-in decoder: the 'messages' are rows of outputs already."""
    rows = np.array(kept, float)
    return np.zeros(len(rows), np.int64), rows, ['LMC6522'] * len(rows)


def test_the_share_counts_the_samples_beyond_the_support_and_names_the_component():
    calibration = supported_calibration()
    active = activate(calibration, 'cubic', 'upright')
    loads = loads_with_some_outside(20, [3, 7, 11, 19])
    sampler = SupportSampler()
    sampler.keep(list(outputs_of(calibration, loads)), decode_rows, 1.0)
    share = sampler.judge(active, None, 20)
    assert share.share == pytest.approx(4 / 20)
    assert (share.checked, share.outside, share.components) == (20, 4, ('FZ',))
    # all inside: a share of zero, not None
    sampler.keep(list(outputs_of(calibration, loads_with_some_outside(20, []))), decode_rows, 1.0)
    inside = sampler.judge(active, None, 20)
    assert inside.share == 0.0 and inside.components == ()


def test_the_share_is_read_with_the_electrical_zero_and_the_input_scale():
    calibration = supported_calibration()
    active = activate(calibration, 'cubic', 'upright')
    outputs = outputs_of(calibration, loads_with_some_outside(10, [0, 1]))
    zero_mv = np.full(6, 0.05)
    sampler = SupportSampler()
    # the bridges report in V/V at 5 V excitation over a zero of 0.05 mV
    sampler.keep(list((outputs + zero_mv) / 5000.0), decode_rows, 5000.0)
    assert sampler.judge(active, zero_mv, 10).share == pytest.approx(0.2)


def test_a_large_leverage_is_outside_for_every_component():
    # the leverage bound of the support (coverage/support.py, case 2) below what the loads reach
    calibration = supported_calibration(leverage_max=1e-12)
    active = activate(calibration, 'cubic', 'upright')
    sampler = SupportSampler()
    sampler.keep(list(outputs_of(calibration, loads_with_some_outside(5, []))), decode_rows, 1.0)
    share = sampler.judge(active, None, 5)
    assert share.share == 1.0 and share.components == COMPONENTS


def test_a_stream_is_subsampled_at_the_previous_periods_rate_whatever_the_batch_size():
    calibration = supported_calibration()
    active = activate(calibration, 'cubic', 'upright')
    sampler = SupportSampler(per_period=100)
    sampler.judge(active, None, 1000)  # the previous period: 1000 samples -> every 10th
    assert sampler.stride == 10
    loads = loads_with_some_outside(1000, np.arange(0, 1000, 5))  # one in five outside
    rows = list(outputs_of(calibration, loads))
    at = 0
    for size in [1, 3, 7, 1, 250, 2, 500, 236]:  # batches of any size, 1000 samples in all
        sampler.keep(rows[at : at + size], decode_rows, 1.0)
        at += size
    assert at == 1000
    share = sampler.judge(active, None, 1000)
    # every 10th sample from the first: indices 0, 10, ... are all multiples of 5, so outside
    assert share.checked == 100 and share.share == 1.0


def test_without_a_recorded_support_the_share_is_not_judged():
    calibration = calibration_with_covariance()  # the memo's: no schedule support recorded
    active = activate(calibration, 'cubic', 'upright')
    sampler = SupportSampler()
    sampler.keep([np.zeros(6)], decode_rows, 1.0)
    share = sampler.judge(active, None, 1)
    assert share.share is None and 'records no schedule support' in share.reason


def diagnostics_values(reports):
    calibration = next(r for r in reports if r.name.endswith(': calibration'))
    return calibration, dict(calibration.values)


def test_diagnostics_warn_while_samples_are_outside_and_are_ok_again_inside():
    calibration = supported_calibration()
    live = LiveCalibrator(activate(calibration, 'cubic', 'upright'))
    encoder = WrenchEncoder('tunnel')
    report = {
        'period_s': 1.0,
        'last_sample_age_s': 0.0,
        'temperature_age_s': None,
        'refit_running': False,
        'tare_source': 'not persisted',
        'node_name': 'balance_calibrator',
    }

    def feed(loads, first):
        stamps = (first + np.arange(len(loads))) * 1_000_000
        for message in serialized(outputs_of(calibration, loads), stamps):
            live.process_messages(
                [message], now_s=0.0, decode=decode_wrenches, input_scale=1.0, encoder=encoder
            )

    feed(loads_with_some_outside(40, np.arange(0, 40, 4), 'MY'), 0)
    status, values = diagnostics_values(live.report(**report))
    assert status.level == WARN
    assert values['outside_support_share'] == '0.2500'
    assert values['outside_support_components'] == 'MY'
    assert values['outside_support_checked'] == '10 of 40 samples'
    assert "25.0 % of the last period's samples outside the calibration's support (MY)" in (
        status.message
    )
    feed(loads_with_some_outside(40, []), 40)
    status, values = diagnostics_values(live.report(**report))
    assert status.level == OK
    assert values['outside_support_share'] == '0.0000'
