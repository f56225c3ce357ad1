"""The live calibrator's lone sample (the usual case at 1 kHz: every sample arrives alone) in one C
call.

At 1 kHz each sample wakes the node by itself, so the per-call cost of Python and numpy -- tripled
by caches gone cold between samples -- is what a sample costs: about 190 µs of the calibrator's CPU
per sample went to decoding, the dozen numpy calls of the one-sample path, the uncertainty and
encoding. `_sample_kernel.c` does those steps for one serialized sample in one call and returns the
serialized wrench and uncertainty: the pure core's only accelerator, called by the live path's one
entry point (stream.LiveCalibrator.process_messages) for the leading samples of a batch it takes;
the bookkeeping (input monitor, counters, overload) is the pure core's, fed once per batch.

It applies only where its result is the pure core's (test/live/test_sample_kernel.py holds them
equal to 1e-12): a direct polynomial model of the bridge outputs alone (no temperature or
load-history terms, no absolute values, powers up to 3), no low-pass, no tare window collecting, no
overload being held. Everything else -- and any sample the kernel declines (a layout it does not
know, a non-finite, saturated or huge output, a non-finite load) -- goes through the pure core,
which also says why. Without the compiled module (no C compiler when installing), or with the
environment variable BALANCE_CALIB_LONE_KERNEL=0, `available` is False and every sample takes the
pure core's path; the node says so once at start-up.
"""

from __future__ import annotations

import os

import numpy as np
from numpy.typing import ArrayLike

from ..array_types import FloatArray
from ..model.active_calibration import ActiveCalibration
from ..model.uncertainty import covariance_and_sigma
from ..units import COMPONENTS
from .tare_store import TareState

try:
    from . import _sample_kernel

    available, unavailable_reason = True, ''
except ImportError as err:  # built without a C compiler: the pure core does every sample
    _sample_kernel, available, unavailable_reason = None, False, str(err)
# the pure core for every sample (A/B, debugging)
if os.environ.get('BALANCE_CALIB_LONE_KERNEL', '1') == '0':
    available, unavailable_reason = False, 'switched off by BALANCE_CALIB_LONE_KERNEL=0'


# what `run` returns for a sample the kernel took (see its docstring)
SingleResult = tuple[
    int, bytes, tuple[float, float, float, float, float, float], bool, bool, bytes, bytes | None
]


def make_plan(
    active: ActiveCalibration, tare: TareState, input_scale: float, middle: bytes
) -> object | None:
    """The kernel's plan for this calibration (ActiveCalibration), zero and tare (TareState), input
    scale and output frame (WrenchEncoder.middle); None where the kernel does not apply.
    """
    if not available or active.model.extra_variables or active.requires or active.iterative:
        return None
    index = active.one_sample_index
    if index is None:
        return None
    model = active.model
    positions = [COMPONENTS.index(c) for c in model.components]
    has_component = np.zeros(6, np.int64)
    has_component[positions] = 1
    sigma2 = np.zeros(6)
    pieces = covariance_and_sigma(model)
    covariance = None
    if pieces is not None:
        covariance = np.ascontiguousarray(pieces[0], dtype=float)
        sigma2[positions] = pieces[1] ** 2
    tare2 = np.zeros(6)
    if tare.tare_sigma is not None:
        tare2[positions] = np.asarray(tare.tare_sigma, dtype=float)[positions] ** 2
    permutation, signs = active.installation.permutation, active.installation.signs

    def six(values: ArrayLike | None) -> FloatArray:
        return np.ascontiguousarray(np.zeros(6) if values is None else values, dtype=float)

    return _sample_kernel.plan(
        float(input_scale),
        six(tare.zero_mv),
        six(active.output_range_mv),
        six(active.envelope),
        six(active.capacity),
        six(tare.tare_load),
        np.ascontiguousarray(permutation, dtype=np.int64),
        six(signs),
        index.shape[0],
        index.shape[1],
        np.ascontiguousarray(index, dtype=np.intp),
        np.ascontiguousarray(active.coefficients_six, dtype=float),
        covariance,
        sigma2,
        tare2,
        has_component,
        bytes(middle),
    )


def run(
    plan: object,
    data: bytes,
    want_uncertainty: bool,
    overload_fraction: float,
    peak_fraction: np.ndarray,
) -> SingleResult | None:
    """One serialized sample -> None (the pure core's turn) or (stamp_ns, frame_id bytes, loads
    (6,) balance axes before the tare, outside the envelope, beyond overload_fraction x capacity,
    wrench bytes, uncertainty bytes or None). peak_fraction (6,) float64, the overload monitor's:
    updated in place with this sample's |load| / capacity.
    """
    return _sample_kernel.run(plan, data, want_uncertainty, overload_fraction, peak_fraction)
