"""`balance-calib reduce`: wind-on bags -> held points -> coefficients through one or several
calibration models (TM-663 §10.3-10.4, Figs. 12-13). The steps are those of the live node
(`aero_coefficients`): the calibration without its constants evaluated on the full bridge outputs
and turned into the installation's tunnel axes as `balance_calibrator` does, then run.py.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from ..calibration_file import load_calibration
from ..coverage.run import run_coverage, RunCoverage
from ..model.active_calibration import activate, six_axis_loads
from ..model.calibration import Calibration
from ..model.uncertainty import has_uncertainty
from ..tunnel_axes import Installation, parse_installation
from .bag_io import DEFAULT_MAX_INPUT_AGE_S, read_run, RunSamples
from .held_points import HoldSettings
from .model_file import load_model, ModelDescription
from .run import FALLBACK_SIGMA_PCT_FS, offset_warnings, RunResult, sigma_loads_tunnel
from .zero_drift import drift_pct_fs, drift_warnings, reduce_run_with_drift, ZeroDrift


class ReduceError(ValueError):
    """Bad input to the reduction; one line naming the file, topic or option."""


@dataclass(frozen=True)
class ModelRun:
    name: str  # calibration model: 'cubic', 'linear', ...
    result: RunResult
    zero_drift: ZeroDrift = ZeroDrift('none', reason='not measured')
    # the shift in % FS of the calibration's components (balance axes); None without a shift
    zero_shift_pct_fs: np.ndarray | None = None


@dataclass(frozen=True)
class Reduction:
    samples: RunSamples
    calibration: Calibration
    calibration_path: str
    model: ModelDescription
    installation: Installation
    settings: HoldSettings
    sigma_loads: np.ndarray  # (6,) tunnel axes
    sigma_source: str
    main: ModelRun
    compared: tuple[ModelRun, ...]
    # predicted u of the main model at every sample; None: the calibration carries no coefficient
    # covariance
    coverage: RunCoverage | None = None
    # the electrical zero subtracted in output space and where it came from ('' = none)
    electrical_zero_mv: np.ndarray | None = None
    electrical_zero_source: str = ''

    @property
    def runs(self) -> tuple[ModelRun, ...]:
        return (self.main,) + tuple(r for r in self.compared)


def calibration_sigma(
    calibration: Calibration, installation: Installation
) -> tuple[np.ndarray, str]:
    sigma = [calibration.sigma_pct_fs.get(c) for c in calibration.components]
    if len(calibration.components) == 6 and all(s is not None and s > 0 for s in sigma):
        return sigma_loads_tunnel(
            sigma, calibration.capacity, installation
        ), "the calibration's σ (% FS)"
    return sigma_loads_tunnel(
        [FALLBACK_SIGMA_PCT_FS] * 6, calibration.capacity, installation
    ), f'none stated by the calibration: {FALLBACK_SIGMA_PCT_FS} % FS assumed'


def calibration_sigma_pct_fs(calibration: Calibration) -> np.ndarray:
    """(6,) the calibration's σ per component, % FS (FALLBACK_SIGMA_PCT_FS where none stated)."""
    stated = [calibration.sigma_pct_fs.get(c) for c in calibration.components]
    return np.array([s if s is not None and s > 0 else FALLBACK_SIGMA_PCT_FS for s in stated])


def readings_for(
    calibration: Calibration, model_name: str, installation: Installation, raw_mv
) -> np.ndarray:
    """Calibrated loads in the tunnel axes of §10.2, as balance_calibrator publishes them (no
    tare).
    """
    active = activate(calibration, model_name, installation)
    if active.requires:
        raise ReduceError(
            f'calibration model {active.model_name!r} needs {", ".join(active.requires)} as '
            'well as the bridge outputs; choose another with --calibration-model or --compare'
        )
    return installation.to_tunnel(six_axis_loads(active.model, raw_mv))


# no bridge gives 1000x its rated output (the refit's cut uses the same bound, load_points.py)
IMPLAUSIBLE_OUTPUT_RATED = 1000.0


def _without_implausible_outputs(samples: RunSamples, calibration: Calibration):
    """The samples less those whose bridge outputs are beyond IMPLAUSIBLE_OUTPUT_RATED x rated (a
    flipped exponent bit: through a cubic it overflows and spoils the hold's mean), and the
    warning saying how many went (an empty list when none).
    """
    raw = np.asarray(samples.raw_mv, float)
    limit = IMPLAUSIBLE_OUTPUT_RATED * np.abs(np.asarray(calibration.rated_output_mv, float))
    bad = np.any(np.abs(raw) > limit, axis=1)
    if not bad.any():
        return samples, []
    first = int(np.flatnonzero(bad)[0])
    k = int(np.argmax(np.abs(raw[first]) / limit))
    keep = ~bad

    def kept(values):
        return None if values is None else values[keep]

    warning = (
        f'{int(bad.sum())} raw sample(s) with a bridge output beyond '
        f'{IMPLAUSIBLE_OUTPUT_RATED:g}x its rated output left out (first: '
        f'{calibration.bridge_outputs[k]} {raw[first, k]:.4g} mV)'
    )
    return replace(
        samples,
        stamps_ns=samples.stamps_ns[keep],
        raw_mv=raw[keep],
        support_attitude=samples.support_attitude[keep],
        q_pa=samples.q_pa[keep],
        truth_body=kept(samples.truth_body),
        truth_wind=kept(samples.truth_wind),
    ), [warning]


def zero_from_the_bag(samples: RunSamples, calibration: Calibration):
    """The electrical zero a live balance_calibrator of this balance stated in the bag's
    /diagnostics (its ~/zero), where it came from, and warnings; (None, '', []) when none did.
    """
    mine = [
        (node, zero)
        for node, balance, zero in samples.stated_zeros
        if balance.lower() == calibration.balance.lower()
    ]
    if not mine:
        return None, '', []
    node, zero = mine[0]
    source = f"{node}'s ~/zero, stated in the bag's /diagnostics"
    others = [z for _, z in mine if np.max(np.abs(z - zero)) > 0]
    warnings = []
    if others:
        warnings.append(
            f'the electrical zero stated in /diagnostics changed during the run (by up to '
            f'{np.max(np.abs(np.array(others) - zero)):.5f} mV); the first one is used: '
            'give --electrical-zero-mv to choose'
        )
    return zero, source, warnings


@dataclass(frozen=True)
class ReduceOptions:
    """How `reduce` treats a run (its options; the defaults are the command's).

    compare: other calibration models to reduce the run through; calibration_model: the model of
    the main columns ('adopted': the calibration's); installation: upright, inverted or a signed
    permutation; settings: how holds are found and averaged; max_input_age_s: attitude and q∞
    older than this at a raw sample make it stale; estimate_weight: weight and CG from the
    wind-off sweep even if the model file declares them; raw_topic, attitude_topic,
    dynamic_pressure_topic: the topics in the bags.
    electrical_zero_mv (6,): the bridge outputs with nothing on the balance (the calibrator's
    ~/zero), subtracted from the raw outputs before the calibration (output space, exact for any
    model); what remains constant is taken by the wind-off sweep's offsets in load space. None:
    the zero a live balance_calibrator of this balance stated in the bags' /diagnostics (the
    ~/zero it had taken while the run was recorded), if one did.
    zero_drift 'linear' | 'none': the offsets interpolated in time between the pre-run and
    post-run wind-off sweeps, or the pre-run ones throughout (zero_drift.py).
    """

    compare: Sequence[str] = ()
    calibration_model: str = 'adopted'
    installation: str = 'upright'
    settings: HoldSettings = HoldSettings()
    max_input_age_s: float = DEFAULT_MAX_INPUT_AGE_S
    estimate_weight: bool = False
    raw_topic: str = '/balance/raw'
    attitude_topic: str = '/model/attitude'
    dynamic_pressure_topic: str = '/tunnel/dynamic_pressure'
    electrical_zero_mv: Sequence[float] | np.ndarray | None = None
    zero_drift: str = 'linear'


def reduce_bags(
    bags: Sequence[str | Path],
    calibration_path: str,
    model_path: str,
    options: ReduceOptions = ReduceOptions(),
) -> Reduction:
    """Everything `reduce` computes, as `options` say (ReduceOptions). Raises ReduceError (or
    ConfigError/BagError) naming the input.
    """
    compare, calibration_model, installation, settings = (
        options.compare,
        options.calibration_model,
        options.installation,
        options.settings,
    )
    max_input_age_s, electrical_zero_mv = options.max_input_age_s, options.electrical_zero_mv
    try:
        calibration = load_calibration(calibration_path)
        model = load_model(model_path)
        parsed = parse_installation(installation)
    except ValueError as err:  # ConfigError too
        raise ReduceError(str(err)) from None
    if options.estimate_weight:
        model = model.with_estimated_weight()
    main_name = calibration.adopted if calibration_model in ('adopted', '') else calibration_model
    names = [main_name] + [n for n in compare if n != main_name]
    for name in names:
        if name not in calibration.models:
            raise ReduceError(
                f'{calibration_path}: no {name!r} model (it has {", ".join(calibration.models)})'
            )
    samples = read_run(
        bags,
        raw_topic=options.raw_topic,
        attitude_topic=options.attitude_topic,
        dynamic_pressure_topic=options.dynamic_pressure_topic,
        max_input_age_s=max_input_age_s,
    )
    if len(samples.q_pa) == 0:
        raise ReduceError(
            f'{", ".join(map(str, bags))}: no raw sample has an attitude and a dynamic pressure '
            f'within {max_input_age_s} s before it'
        )
    samples, implausible = _without_implausible_outputs(samples, calibration)
    if len(samples.q_pa) == 0:
        raise ReduceError(f'{", ".join(map(str, bags))}: {implausible[0]}; no sample left')
    zero_source = '--electrical-zero-mv' if electrical_zero_mv is not None else ''
    if electrical_zero_mv is None:
        electrical_zero_mv, zero_source, zero_warnings = zero_from_the_bag(samples, calibration)
        implausible = implausible + zero_warnings
    sigma, sigma_source = calibration_sigma(calibration, parsed)
    runs: list[ModelRun] = []
    raw = (
        samples.raw_mv
        if electrical_zero_mv is None
        else samples.raw_mv - np.asarray(electrical_zero_mv, float)
    )
    coverage = (
        run_coverage(calibration, outputs_mv=raw, model=main_name)
        if has_uncertainty(calibration, main_name)
        else None
    )
    times_s = (samples.stamps_ns - samples.stamps_ns[0]) / 1e9
    for name in names:
        readings = readings_for(calibration, name, parsed, raw)
        try:
            result, drift = reduce_run_with_drift(
                readings,
                samples.support_attitude,
                samples.q_pa,
                times_s,
                model,
                settings,
                sigma,
                options.zero_drift,
            )
        except ValueError as err:  # the mode
            raise ReduceError(str(err)) from None
        capacity = parsed.to_tunnel(np.asarray(calibration.capacity, float))
        extra = offset_warnings(result.tares, capacity, name, electrical_zero_mv is not None)
        shift_pct = None
        if drift.shift is not None and len(calibration.components) == 6:
            shift_pct = drift_pct_fs(drift.shift, calibration.capacity, parsed)
            extra += drift_warnings(
                drift,
                calibration.components,
                shift_pct,
                calibration_sigma_pct_fs(calibration),
                name,
            )
        extra = (implausible if not runs else []) + extra
        runs.append(
            ModelRun(
                name,
                replace(result, warnings=result.warnings + tuple(extra)),
                drift,
                shift_pct,
            )
        )
    if not runs[0].result.wind_on:
        raise ReduceError(
            f'{", ".join(map(str, bags))}: no held wind-on attitude found '
            f'(q∞ ≥ {settings.wind_off_q_pa} Pa held for {settings.min_samples} samples or more)'
        )
    return Reduction(
        samples,
        calibration,
        str(calibration_path),
        model,
        parsed,
        settings,
        sigma,
        sigma_source,
        runs[0],
        tuple(runs[1:]),
        coverage,
        None if electrical_zero_mv is None else np.asarray(electrical_zero_mv, float),
        zero_source,
    )
