"""The live benchmark's summary (benchmarks/loss_summary.py): what counts as zero loss, worked
by hand on made-up steps, so that the README's rates mean what its text says they mean.
"""

import math

from balance_calib.benchmarks.loss_summary import (
    cpu_budget,
    first_loss_rate,
    medians_at_1k,
    zero_loss_rate,
)


def step(
    rate, received=None, uncertainty=0, achieved=None, cpu=100.0, p99=0.5, source=20.0, sink=30.0
):
    sent = int(rate * 3)
    return {
        'rate': float(rate),
        'sent': sent,
        'received': sent if received is None else received,
        'uncertainty_received': uncertainty,
        'achieved': float(rate) if achieved is None else achieved,
        'cpu_us_per_sample': cpu,
        'p50_ms': 0.2,
        'p99_ms': p99,
        'source_us_per_sample': source,
        'sink_us_per_sample': sink,
    }


def test_zero_loss_is_the_top_rate_with_every_trial_whole_and_first_loss_the_lowest_not():
    # one trial of 4 kHz lost one
    results = [
        step(1000),
        step(1000),
        step(4000),
        step(4000, received=11999),
        # 12 kHz: one whole, one not
        step(8000),
        step(8000),
        step(12000),
        step(12000, received=0),
    ]
    # 8 kHz whole twice, above a lossy 4 kHz: reported as run
    assert zero_loss_rate(results) == 8000.0
    assert first_loss_rate(results) == 4000.0


def test_a_step_sent_below_95_percent_of_its_rate_is_not_zero_loss():
    results = [step(1000), step(2000, achieved=1890.0)]
    assert zero_loss_rate(results) == 1000.0 and first_loss_rate(results) == 2000.0


def test_the_second_topic_must_come_back_whole_too_when_the_row_published_it():
    two = [step(1000, uncertainty=3000), step(2000, uncertainty=5999)]
    assert zero_loss_rate(two) == 1000.0 and first_loss_rate(two) == 2000.0
    one = [step(1000), step(2000)]  # a row with no second topic at all
    assert zero_loss_rate(one) == 2000.0 and math.isnan(first_loss_rate(one))
    assert zero_loss_rate([step(1000, received=2999)]) == 0.0


def test_the_1khz_figures_are_medians_over_the_trials():
    results = [
        step(1000, cpu=150.0, p99=0.4),
        step(1000, cpu=120.0, p99=1.3),
        step(1000, cpu=130.0, p99=0.5),
        step(2000, cpu=1.0, p99=9.0),
    ]
    assert medians_at_1k(results) == {'cpu_us_per_sample': 130.0, 'p50_ms': 0.2, 'p99_ms': 0.5}
    assert medians_at_1k([step(2000)]) is None


def test_the_cpu_budget_is_at_the_top_rate_with_every_row_whole_as_medians_of_its_trials():
    summary = {
        'a': [
            step(8000, cpu=30.0),
            step(8000, cpu=34.0),
            step(8000, cpu=32.0),
            step(12000, cpu=1.0),
            step(12000, cpu=1.0),
        ],
        'b': [
            step(8000, cpu=50.0, sink=40.0, uncertainty=24000),
            step(8000, cpu=70.0, sink=44.0, uncertainty=24000),
            step(8000, cpu=60.0, sink=42.0, uncertainty=24000),
            # 12 kHz: one trial lost one
            step(12000, uncertainty=36000),
            step(12000, uncertainty=35999),
        ],
    }
    rate, rows = cpu_budget(summary, ('a', 'b'))
    assert rate == 8000.0  # 12 kHz was whole for 'a' only
    assert rows['a'] == {'node': 32.0, 'source': 20.0, 'sink': 30.0, 'total': 82.0}
    assert rows['b'] == {'node': 60.0, 'source': 20.0, 'sink': 42.0, 'total': 122.0}
    assert cpu_budget(summary, ('a', 'missing')) is None
    assert cpu_budget({'a': [step(1000, received=1)]}, ('a',)) is None
