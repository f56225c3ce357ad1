"""Timing helpers shared by the benchmark scripts."""

from __future__ import annotations

import time


def best_of(function, repeat: int) -> float:
    """The shortest of `repeat` wall-clock runs of function(), s (the least disturbed one)."""
    best = float('inf')
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best
