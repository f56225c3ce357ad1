"""The share of a diagnostics period's samples outside the active calibration's support.

A tunnel load that combines the components beyond anything the calibration schedule applied is
extrapolated, even when each load alone is within range (coverage/support.py; `coverage` and
`reduce` judge a run the same way). balance_calibrator says so in /diagnostics while it happens:
key `outside_support_share`, WARN while it is not zero.

The judgement costs a design row and a leverage per sample, so it stays off the hot path: the
stream keeps a reference to every `stride`-th serialized sample of a batch (a slice of a list,
whatever the batch size), at most SAMPLES_PER_PERIOD a period, and the diagnostics tick decodes
and judges those at once, vectorised (coverage/run.py's outside_support_of_outputs), outside the
lock the samples wait for (`take`; 3-7 ms for 250 samples of the cubic model on a busy 2-core
machine). The stride follows the previous period's rate, so a period judges about
SAMPLES_PER_PERIOD samples whatever the rate: a share below 1/SAMPLES_PER_PERIOD may read 0.
Samples are read with the electrical zero in force at the tick.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..coverage.run import outside_support_of_outputs, recorded_support
from ..model.active_calibration import ActiveCalibration
from ..units import BRIDGE_OUTPUTS

SAMPLES_PER_PERIOD = 250


@dataclass(frozen=True)
class SupportShare:
    """One period's judgement. share None: not judged (`reason` says why)."""

    share: float | None
    checked: int = 0
    outside: int = 0
    components: tuple[str, ...] = ()  # components outside for some sample
    reason: str = ''


class SupportSampler:
    """Every stride-th sample of the stream, kept as received (bytes), judged per period."""

    def __init__(self, per_period: int = SAMPLES_PER_PERIOD) -> None:
        self.per_period = int(per_period)
        self.stride = 1
        self.phase = 0  # samples since the last kept one, modulo stride
        self.kept: list[bytes] = []
        self.decode: Callable | None = None
        self.input_scale = 1.0

    def keep(self, messages: Sequence[bytes], decode: Callable, input_scale: float) -> None:
        """The hot path's part: O(1) Python operations a batch."""
        stride = self.stride
        start = -self.phase % stride
        self.phase = (self.phase + len(messages)) % stride
        if start < len(messages) and len(self.kept) < self.per_period:
            self.kept.extend(messages[start::stride])
        self.decode, self.input_scale = decode, input_scale

    def judge(
        self, active: ActiveCalibration, zero_mv: ArrayLike | None, received_in_period: int
    ) -> SupportShare:
        """The share of the kept samples outside the support; starts the next period."""
        return self.take(active, zero_mv, received_in_period)()

    def take(
        self, active: ActiveCalibration, zero_mv: ArrayLike | None, received_in_period: int
    ) -> Callable[[], SupportShare]:
        """The period's kept samples and a call that judges them (to run under no lock); starts
        the next period.
        """
        kept, self.kept = self.kept, []
        self.stride = max(1, math.ceil(received_in_period / self.per_period))
        self.phase = 0
        decode, input_scale = self.decode, self.input_scale
        return lambda: judge_samples(kept, decode, input_scale, active, zero_mv)


def judge_samples(
    kept: Sequence[bytes],
    decode: Callable | None,
    input_scale: float,
    active: ActiveCalibration,
    zero_mv: ArrayLike | None,
) -> SupportShare:
    """The share of serialized samples outside the active calibration's recorded support."""
    calibration = active.calibration
    support = recorded_support(calibration)
    if support is None:
        return SupportShare(None, reason='the calibration records no schedule support')
    if not kept or decode is None:
        return SupportShare(None, reason='no sample in the period')
    _, outputs, _ = decode(kept)
    outputs = np.asarray(outputs, float) * input_scale
    if zero_mv is not None:
        outputs = outputs - np.asarray(zero_mv, float)
    model = calibration.model(active.model_name)
    outputs = outputs[:, [BRIDGE_OUTPUTS.index(name) for name in model.inputs]]
    outputs = outputs[np.all(np.isfinite(outputs), axis=1)]  # rejected: counted elsewhere
    if not len(outputs):
        return SupportShare(None, reason='no finite sample in the period')
    outside = outside_support_of_outputs(
        calibration, outputs, model=active.model_name, support=support
    )
    if outside is None:
        return SupportShare(
            None, reason=f"the support's {support.model} model carries no coefficient covariance"
        )
    components = tuple(c for c, out in zip(calibration.components, np.any(outside, axis=0)) if out)
    n_outside = int(np.count_nonzero(np.any(outside, axis=1)))
    return SupportShare(n_outside / len(outputs), len(outputs), n_outside, components)
