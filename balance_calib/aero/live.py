"""What node `aero_coefficients` computes, without rclpy: a stream of calibrated wrenches,
attitudes and dynamic pressures -> per-sample coefficients and held points (the same steps as
`reduce`).

Matching by stamp: a wrench sample (stamp t) takes the latest attitude and q∞ stamped at or before
t. It waits (`pending`) until both inputs have been seen at or after t, because the three topics
arrive independently (a reliable topic may lag while DDS repeats a lost packet); `flush(now)` then
settles samples that have waited longer than `match_wait_s` since they arrived with what there is.
A sample whose attitude or q∞ is missing or older than `max_input_age_s` is stale: it is counted
and dropped, as `reduce` drops it (bag_io.match_latest).

Besides the automatic point of every hold, `request_point(n)` takes one on demand (the node's
~/take_point service): the next n wind-on samples, all in the same hold; `request` then holds the
outcome (done, message, point). The attitude or q∞ changing first, or wind-off, fails it.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from .coefficients import reduce_loads, Reduced
from .held_points import HoldSettings, HoldTracker
from .model_file import ModelDescription
from .run import held_point, HeldPoint, TareTracker

HISTORY = 4096  # attitude / q∞ messages kept for matching


@dataclass(frozen=True)
class SampleResult:
    stamp_ns: int
    reduced: Reduced


@dataclass(frozen=True)
class LivePoint:
    stamp_ns: int  # stamp of the last sample in the point
    point: HeldPoint


@dataclass
class PointRequest:
    samples: int
    hold: int | None = None
    rows: list = field(default_factory=list)
    done: bool = False
    success: bool = False
    message: str = ''
    point: HeldPoint | None = None
    stamp_ns: int = 0

    def finish(
        self, success: bool, message: str, point: HeldPoint | None = None, stamp_ns: int = 0
    ):
        self.done, self.success, self.message, self.point, self.stamp_ns = (
            True,
            success,
            message,
            point,
            stamp_ns,
        )


@dataclass
class LiveCounters:
    samples: int = 0
    stale: int = 0
    wind_off: int = 0
    not_reduced: int = 0  # wind-on samples without a tare yet
    points: int = 0
    last_stale_reason: str = ''


class _Latest:
    """Stamped inputs, newest last; latest at or before a stamp."""

    def __init__(self):
        self.stamps: deque[int] = deque(maxlen=HISTORY)
        self.values: deque[np.ndarray] = deque(maxlen=HISTORY)

    def add(self, stamp_ns: int, value) -> None:
        if self.stamps and stamp_ns < self.stamps[-1]:  # out of order: keep the deque sorted
            items = sorted(
                zip(
                    list(self.stamps) + [stamp_ns], list(self.values) + [np.asarray(value, float)]
                ),
                key=lambda item: item[0],
            )
            self.stamps.clear(), self.values.clear()
            for s, v in items:
                self.stamps.append(s), self.values.append(v)
            return
        self.stamps.append(int(stamp_ns))
        self.values.append(np.asarray(value, float))

    @property
    def newest(self) -> int | None:
        return self.stamps[-1] if self.stamps else None

    def at(self, stamp_ns: int):
        for index in range(len(self.stamps) - 1, -1, -1):
            if self.stamps[index] <= stamp_ns:
                return self.stamps[index], self.values[index]
        return None


class LiveReduction:
    def __init__(
        self,
        model: ModelDescription,
        settings: HoldSettings,
        sigma_loads,
        max_input_age_s: float = 0.5,
        match_wait_s: float = 2.0,
    ):
        if not max_input_age_s > 0 or not match_wait_s > 0:
            raise ValueError(
                f'max_input_age_s and match_wait_s must be positive, not {max_input_age_s}, '
                f'{match_wait_s}'
            )
        self.match_wait_ns = int(round(match_wait_s * 1e9))
        self.model, self.settings = model, settings
        self.sigma_loads = np.asarray(sigma_loads, float)
        self.max_age_ns = int(round(max_input_age_s * 1e9))
        self.tracker = TareTracker(model, self.sigma_loads)
        self.holds = HoldTracker(settings)
        self.counters = LiveCounters()
        self._attitude, self._q = _Latest(), _Latest()
        self._pending: deque[tuple[int, np.ndarray, int]] = deque()  # (stamp, loads, arrival) ns
        # current hold's (stamp, reading, attitude, q)
        self._hold: list[tuple[int, np.ndarray, np.ndarray, float]] = []
        self._hold_index = -1
        self._hold_taken = False
        self.last_stamp_ns = 0  # stamp of the last sample processed (a point's stamp)
        self.request: PointRequest | None = None

    # --- inputs ---------------------------------------------------------------------------------
    def add_attitude(self, stamp_ns: int, attitude) -> tuple[list[SampleResult], list[LivePoint]]:
        self._attitude.add(stamp_ns, attitude)
        return self._drain(None)

    def add_dynamic_pressure(
        self, stamp_ns: int, q_pa: float
    ) -> tuple[list[SampleResult], list[LivePoint]]:
        self._q.add(stamp_ns, [q_pa])
        return self._drain(None)

    def add_wrench(
        self, stamp_ns: int, loads, arrival_ns: int | None = None
    ) -> tuple[list[SampleResult], list[LivePoint]]:
        """arrival_ns: when it was received (node clock); None: its stamp (simulated time)."""
        self._pending.append(
            (
                int(stamp_ns),
                np.asarray(loads, float),
                int(stamp_ns if arrival_ns is None else arrival_ns),
            )
        )
        return self._drain(None)

    def flush(self, now_ns: int) -> tuple[list[SampleResult], list[LivePoint]]:
        """Settle samples that have waited longer than match_wait_s for their inputs."""
        return self._drain(now_ns)

    # --- processing -----------------------------------------------------------------------------
    def _drain(self, now_ns):
        samples, points = [], []
        while self._pending:
            stamp, loads, arrival = self._pending[0]
            complete = all(
                s.newest is not None and s.newest >= stamp for s in (self._attitude, self._q)
            )
            if not complete and (now_ns is None or now_ns - arrival <= self.match_wait_ns):
                break
            self._pending.popleft()
            self._process(stamp, loads, samples, points)
        return samples, points

    def _process(self, stamp: int, loads: np.ndarray, samples: list, points: list) -> None:
        self.counters.samples += 1
        self.last_stamp_ns = stamp
        attitude, q = self._attitude.at(stamp), self._q.at(stamp)
        reason = ''
        if attitude is None or q is None:
            reason = 'no attitude' if attitude is None else 'no dynamic pressure'
        elif stamp - attitude[0] > self.max_age_ns or stamp - q[0] > self.max_age_ns:
            reason = 'attitude' if stamp - attitude[0] > self.max_age_ns else 'dynamic pressure'
            reason += f' older than {self.max_age_ns * 1e-9:g} s'
        elif not (
            np.all(np.isfinite(loads))
            and np.all(np.isfinite(attitude[1]))
            and np.isfinite(q[1][0])
        ):
            reason = 'NaN in the wrench, attitude or dynamic pressure'
        if reason:
            self.counters.stale += 1
            self.counters.last_stale_reason = reason
            return
        support, q_pa = attitude[1], float(q[1][0])
        new, ready = self.holds.add(support, q_pa)
        if new:
            self._close_hold(points)
            self._hold, self._hold_index, self._hold_taken = [], self._hold_index + 1, False
        self._hold.append((stamp, loads, support, q_pa))
        if self.settings.wind_off(q_pa):
            self.counters.wind_off += 1
        else:
            tare = self.tracker.current()
            if tare is None:
                self.counters.not_reduced += 1
            else:
                samples.append(
                    SampleResult(stamp, reduce_loads(loads, support, q_pa, self.model, tare))
                )
        if ready:
            self._take_point(len(self._hold), points)
        if self.request is not None and not self.request.done:
            self._serve_request(stamp, loads, support, q_pa)

    # --- a point on demand ----------------------------------------------------------------------
    def request_point(self, samples: int) -> PointRequest:
        """Average the next `samples` wind-on samples of the current hold into one point."""
        if int(samples) < 1:
            raise ValueError(f'a point needs at least one sample, not {samples}')
        self.request = PointRequest(int(samples))
        return self.request

    def _serve_request(self, stamp, loads, support, q_pa) -> None:
        request = self.request
        if self.settings.wind_off(q_pa):
            request.finish(False, f'wind off (q∞ = {q_pa:.3g} Pa): no coefficients to average')
            return
        if request.hold is None:
            request.hold = self._hold_index
        elif request.hold != self._hold_index:
            request.finish(
                False,
                f'the attitude or q∞ changed after {len(request.rows)} of {request.samples} '
                f'samples: the point was not held',
            )
            return
        request.rows.append((stamp, loads, support, q_pa))
        if len(request.rows) < request.samples:
            return
        if self.tracker.current() is None:
            request.finish(False, 'no weight tare yet: run a wind-off sweep first')
            return
        readings = np.array([r[1] for r in request.rows])
        attitudes = np.array([r[2] for r in request.rows])
        q = np.array([r[3] for r in request.rows])
        point = held_point(
            self._hold_index,
            0,
            readings,
            attitudes,
            q,
            self.settings,
            self.tracker,
        )
        request.finish(True, f'{request.samples} samples averaged', point, stamp)

    def _close_hold(self, points: list) -> None:
        if self._hold and not self._hold_taken and self.settings.point_samples == 0:
            self._take_point(len(self._hold), points)

    def _take_point(self, stop: int, points: list) -> None:
        chosen = self.settings.point_range(0, stop)
        self._hold_taken = True
        if chosen is None:
            return
        a, b = chosen
        readings = np.array([h[1] for h in self._hold[a:b]])
        support = np.array([h[2] for h in self._hold[a:b]])
        q = np.array([h[3] for h in self._hold[a:b]])
        point = held_point(
            self._hold_index,
            a,
            readings,
            support,
            q,
            self.settings,
            self.tracker,
        )
        self.counters.points += int(not point.wind_off and point.reduced is not None)
        points.append(LivePoint(self._hold[b - 1][0], point))
