"""/diagnostics counts one thing under one name: the input status's message gives this period's
count of lost samples (and the other stamp problems) beside the count since start, and the keys
`<problem>_last_period` and `<problem>_since_start` hold the same two numbers.
"""

import re

from live_cases import MEMO
import numpy as np

from balance_calib.live.diagnostics_status import WARN
from balance_calib.live.stream import LiveCalibrator
from balance_calib.model.active_calibration import activate
from balance_calib.tunnel_axes import UPRIGHT

INTERVAL_NS = 1_000_000  # 1 kHz


def lost(values):
    return values['samples_lost_last_period'], values['samples_lost_since_start']


def report(live):
    status = live.report(
        period_s=1.0,
        last_sample_age_s=0.01,
        temperature_age_s=None,
        refit_running=False,
        tare_source='',
        node_name='n',
    )[0]
    return status, dict(status.values)


def said(message, what='samples lost'):
    """(this period, since start) as the message states them."""
    found = re.search(rf'(\d+) {what}[^;]* in the last 1\.0 s \((\d+) since start\)', message)
    return None if found is None else (int(found.group(1)), int(found.group(2)))


def test_the_message_and_the_keys_give_the_same_two_counts_of_lost_samples():
    live = LiveCalibrator(activate(MEMO, 'cubic', UPRIGHT))
    outputs = np.full((400, 6), 0.1)
    stamps = np.arange(1, 401) * INTERVAL_NS
    # period 1: 300 samples, then a gap of 124 intervals (123 lost), 100 more
    live.process(outputs[:300], stamps[:300], now_s=0.0)
    live.process(
        outputs[:100], stamps[300] + 123 * INTERVAL_NS + np.arange(100) * INTERVAL_NS, now_s=0.0
    )
    status, values = report(live)
    assert status.level == WARN
    assert said(status.message) == (123, 123), status.message
    assert lost(values) == ('123', '123')
    # period 2: 5 lost, one by one (the lone-sample path: one sample a batch)
    last = stamps[300] + 222 * INTERVAL_NS
    for k in range(1, 11):
        gap = 2 if k % 2 else 1  # every other sample follows a lost one
        last += gap * INTERVAL_NS
        live.process(outputs[:1], np.array([last]), now_s=0.0)
    status, values = report(live)
    assert said(status.message) == (5, 128), status.message
    assert lost(values) == ('5', '128')
    assert 'samples_lost_(gaps_in_the_stamps)' not in values  # the ambiguous key is gone
    # period 3: nothing lost: the message says nothing of it, the keys 0 and 128
    live.process(outputs[:10], last + np.arange(1, 11) * INTERVAL_NS, now_s=0.0)
    status, values = report(live)
    assert said(status.message) is None and 'lost' not in status.message, status.message
    assert lost(values) == ('0', '128')


def test_every_stamp_problem_has_its_two_named_counts():
    live = LiveCalibrator(activate(MEMO, 'cubic', UPRIGHT))
    stamps = np.arange(1, 101) * INTERVAL_NS
    live.process(np.full((100, 6), 0.1), stamps, now_s=0.0)
    live.process(np.full((3, 6), 0.1), np.array([stamps[50], stamps[99], 0]), now_s=0.0)
    status, values = report(live)
    for key, what in (
        ('stamps_out_of_order', 'stamps out of order'),
        ('duplicate_stamps', 'duplicate stamps'),
        ('zero_stamps', 'zero stamps'),
    ):
        assert values[f'{key}_last_period'] == values[f'{key}_since_start'] == '1', (key, values)
        assert said(status.message, what) == (1, 1), status.message
