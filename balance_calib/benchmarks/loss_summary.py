"""The live benchmarks' summary of their steps: which rates came back whole (zero loss), the first
that lost a sample, the medians at 1 kHz and the CPU budget per sample of the two cores.

A step is a dict as Harness.run returns it: rate, achieved, sent, received, uncertainty_received,
cpu_us_per_sample, p50_ms, p99_ms, source_us_per_sample, sink_us_per_sample.
"""

from __future__ import annotations

import numpy as np


def _whole(results: list, r: dict) -> bool:
    """Every sample back on every topic (the second topic checked for a row that published on it at
    all: see --calibrator-parameter), sent at >= 95 % of the rate aimed at.
    """
    two_topics = any(other['uncertainty_received'] for other in results)
    return (
        r['received'] == r['sent']
        and r['achieved'] >= 0.95 * r['rate']
        and (not two_topics or r['uncertainty_received'] == r['sent'])
    )


def _whole_rates(results: list) -> set:
    """The rates at which every trial came back whole."""
    return {
        rate
        for rate in {r['rate'] for r in results}
        if all(_whole(results, r) for r in results if r['rate'] == rate)
    }


def zero_loss_rate(results: list) -> float:
    """The highest rate at which every trial came back whole (0 if none did). A lower rate may have
    lost samples in one of its trials (first_loss_rate says which): losses come from scheduling
    stalls on two cores, not from a sharp ceiling.
    """
    lossless = _whole_rates(results)
    return max(lossless) if lossless else 0.0


def first_loss_rate(results: list) -> float:
    """The lowest rate at which some trial lost a sample (NaN if none did)."""
    lost = [r['rate'] for r in results if not _whole(results, r)]
    return min(lost) if lost else float('nan')


def medians_at_1k(results: list) -> dict | None:
    """At 1 kHz: the median over the trials of CPU per sample, p50 and p99 (None if 1 kHz was
    not run).
    """
    ones = [r for r in results if r['rate'] == 1000.0]
    if not ones:
        return None
    return {
        key: float(np.median([r[key] for r in ones]))
        for key in ('cpu_us_per_sample', 'p50_ms', 'p99_ms')
    }


def cpu_budget(summary: dict, labels: tuple) -> tuple[float, dict] | None:
    """The two cores' budget per sample: at the highest rate at which every trial of every row in
    `labels` came back whole, the median over its trials of node, source and sink CPU per sample
    (µs) and their total, per row. Were the two cores what runs out, a row's zero-loss rate would
    go as 1 / total; at 10-12 kHz they are 1.0-1.5 cores busy and the losses come from stalls
    (README), so the ratio of totals is evidence of where the CPU goes, not a prediction of the
    rate. None if some row is missing or no rate is whole in all of them.
    """
    rows = [summary.get(label) for label in labels]
    if any(not row for row in rows):
        return None
    common = set.intersection(*(_whole_rates(row) for row in rows))
    if not common:
        return None
    rate = max(common)
    budget = {}
    for label, row in zip(labels, rows):
        at = [r for r in row if r['rate'] == rate]
        node, source, sink = (
            float(np.median([r[key] for r in at]))
            for key in ('cpu_us_per_sample', 'source_us_per_sample', 'sink_us_per_sample')
        )
        budget[label] = {
            'node': node,
            'source': source,
            'sink': sink,
            'total': node + source + sink,
        }
    return rate, budget
