"""Coverage of a run: the predicted uncertainty of each load of a run, and where it leaves the
calibration schedule's support (support.py).

The predicted standard uncertainty (k = 1) is the one balance_calibrator publishes on
/balance/wrench_uncertainty (model/uncertainty.py: u_k² = σ_k² (1 + x (XᵀX)⁻¹ xᵀ) for a direct
model), without a live tare's scatter. It needs the bridge outputs of each load, because the design
row x of the direct model is a polynomial of the outputs: a run given as loads (a CSV, or the
/balance/wrench a calibrator published) is first turned into the outputs this calibration would
read as those loads, by the calibration's own inverse (model/inverse.py; wind-on form, constants
dropped, as the live node uses it). Its error against the balance's true outputs moves x by about
the calibration's own error, a part in 10⁴ of the leverage: negligible here.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..calibration_file import Calibration
from ..model.inverse import outputs_for_loads
from ..model.uncertainty import covariance_and_sigma, load_standard_uncertainty, require_covariance
from .support import ScheduleSupport, leverage, outside_support

LOADS_BEYOND_CAPACITY = 2.0        # loads beyond this x capacity are not inverted (u is NaN there)


@dataclass(frozen=True)
class RunCoverage:
    """Predicted uncertainty along a run, balance axes, the calibration's components."""

    components: tuple[str, ...]
    capacity: np.ndarray                 # (n,) N / N·m
    loads: np.ndarray                    # (S, n) N / N·m
    uncertainty: np.ndarray              # (S, n) N / N·m, k = 1; NaN where not computable
    outside: np.ndarray | None           # (S, n) bool; None: the calibration records no support
    sigma_pct_fs: Mapping[str, float]    # the calibration's σ
    model_name: str

    @property
    def uncertainty_pct_fs(self) -> np.ndarray:
        return self.uncertainty / self.capacity * 100.0

    def summary(self) -> dict:
        """coverage.json (interfaces.md): points, RMS and worst predicted u in % FS, the share of the
        run outside the support per component (null without a recorded support), the σ."""
        u = self.uncertainty_pct_fs
        finite = np.isfinite(u)
        with np.errstate(invalid='ignore'):
            rms = [float(np.sqrt(np.mean(u[finite[:, k], k] ** 2))) if finite[:, k].any() else None
                   for k in range(len(self.components))]
            worst = [float(np.max(u[finite[:, k], k])) if finite[:, k].any() else None
                     for k in range(len(self.components))]
        outside = [None] * len(self.components) if self.outside is None \
            else [float(np.mean(self.outside[:, k])) for k in range(len(self.components))]
        return {
            'points': int(len(self.loads)),
            'predicted_u_pct_fs': dict(zip(self.components, _rounded(rms))),
            'worst_u_pct_fs': dict(zip(self.components, _rounded(worst))),
            'outside_support_fraction': dict(zip(self.components, _rounded(outside))),
            'sigma_pct_fs': {c: float(self.sigma_pct_fs[c]) for c in self.components if c in self.sigma_pct_fs},
            'model': self.model_name,
            'not_computed': int(np.count_nonzero(~np.all(finite, axis=1))),
        }


def _rounded(values):
    return [None if v is None else round(v, 6) for v in values]


def recorded_support(calibration: Calibration) -> ScheduleSupport | None:
    """The support refit recorded in calibration.yaml (`extra.support`), or None."""
    data = (calibration.extra or {}).get('support')
    if not data:
        return None
    try:
        return ScheduleSupport.from_dict(data, calibration.components, calibration.capacity)
    except (KeyError, TypeError, ValueError):
        return None


def _extra_at_reference(model, loads: np.ndarray) -> dict[str, np.ndarray] | None:
    """Variables besides the outputs that a model needs: at the reference temperature (dT = 0) and
    with each load last rising (dir = +1), for a run known only by its loads."""
    if not model.extra_variables:
        return None
    n = len(loads)
    return {v: (np.ones(n) if v.startswith('dir_') else np.zeros(n)) for v in model.extra_variables}


def run_coverage(calibration: Calibration, loads=None, *, outputs_mv=None, model: str = 'adopted',
                 support: ScheduleSupport | None = None) -> RunCoverage:
    """Predicted u (k = 1) and support at every load of a run.

    Parameters
    ----------
    calibration : the calibration (must carry a coefficient covariance: UncertaintyUnavailable).
    loads : (S, n) loads in N and N·m, balance axes, the calibration's components; or
    outputs_mv : (S, n_inputs) the bridge outputs of the run, mV, zero subtracted (then the loads
        are the model's reading of them).
    support : the schedule's support; default the one recorded in the calibration (refit records
        it; without one, or when its model is gone, RunCoverage.outside is None).
    """
    chosen = calibration.model(model)
    require_covariance(chosen)
    capacity = np.asarray(calibration.capacity, dtype=float)
    if outputs_mv is None:
        loads = np.atleast_2d(np.asarray(loads, dtype=float))
        reachable = np.all(np.isfinite(loads), axis=1) \
            & np.all(np.abs(loads) <= LOADS_BEYOND_CAPACITY * capacity, axis=1)
        outputs_mv = np.full((len(loads), len(chosen.inputs)), np.nan)
        if reachable.any():
            wind_on = chosen.without_constant()
            if getattr(chosen, 'form', 'direct') == 'iterative':
                outputs_mv[reachable] = wind_on.outputs(loads[reachable])
            else:
                outputs_mv[reachable] = outputs_for_loads(wind_on, loads[reachable],
                                                          _extra_at_reference(chosen, loads[reachable]))
    else:
        outputs_mv = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
        loads = chosen.without_constant().loads(outputs_mv, _extra_at_reference(chosen, outputs_mv))
    extra = _extra_at_reference(chosen, loads)
    uncertainty = load_standard_uncertainty(chosen, outputs_mv, extra, loads=loads)
    support = support if support is not None else recorded_support(calibration)
    outside = None
    if support is not None and support.model in calibration.models:
        base = calibration.models[support.model]
        pieces = covariance_and_sigma(base)
        if pieces is not None and not base.extra_variables and getattr(base, 'form', 'direct') == 'direct':
            finite = np.all(np.isfinite(outputs_mv), axis=1)
            load_leverage = np.full(len(loads), np.nan)
            load_leverage[finite] = leverage(base.design(outputs_mv[finite]), pieces[0])
            outside = outside_support(support, loads, load_leverage)
    name = calibration.adopted if model in ('adopted', '') else model
    return RunCoverage(tuple(calibration.components), capacity, loads, uncertainty, outside,
                       dict(calibration.sigma_pct_fs), name)


def summary_table(summary: dict, components) -> str:
    """coverage.json's numbers as a plain-text table (the coverage command's output, and the
    section of reduce's report.md)."""
    computed = summary['not_computed']
    lines = [f'{summary["points"]} loads, model {summary["model"]}'
             + (f' ({computed} not computed: not finite or beyond 2x capacity)' if computed else ''),
             f'{"":22s}' + ''.join(f'{c:>9s}' for c in components)]

    def row(label, values, fmt):
        return f'{label:22s}' + ''.join(
            f'{"n/a" if values.get(c) is None else format(values[c], fmt):>9s}' for c in components)
    lines.append(row('predicted u RMS, % FS', summary['predicted_u_pct_fs'], '.4f'))
    lines.append(row('predicted u max, % FS', summary['worst_u_pct_fs'], '.4f'))
    lines.append(row('calibration σ, % FS', summary['sigma_pct_fs'], '.4f'))
    lines.append(row('outside support', summary['outside_support_fraction'], '.1%'))
    if all(v is None for v in summary['outside_support_fraction'].values()):
        lines.append('the calibration records no schedule support (refit records it)')
    return '\n'.join(lines)
