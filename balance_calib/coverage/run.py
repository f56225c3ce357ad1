"""Coverage of a run: the predicted uncertainty of each load of a run, and where it leaves the
calibration schedule's support (support.py).

The predicted standard uncertainty (k = 1) is the one balance_calibrator publishes on
/balance/wrench_uncertainty (model/uncertainty.py: u_k² = σ_k² (1 + x (XᵀX)⁻¹ xᵀ) for a
direct model), without a live tare's scatter. It needs the bridge outputs of each load, because
the design row x of the direct model is a polynomial of the outputs: a run given as loads (a
CSV, or the /balance/wrench a calibrator published) is first turned into the outputs this
calibration would read as those loads, by the calibration's own inverse (model/inverse.py;
wind-on form, constants dropped, as the live node applies it). Its difference from the balance's
true outputs moves x by about the calibration's own error, a part in 10⁴: negligible for u.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..model.calibration import Calibration
from ..model.inverse import outputs_for_loads
from ..model.leverage import leverage_of_rows
from ..model.uncertainty import covariance_and_sigma, load_standard_uncertainty, require_covariance
from .support import outside_support, ScheduleSupport

LOADS_BEYOND_CAPACITY = 2.0  # loads beyond this x capacity are not inverted (u is NaN there)


@dataclass(frozen=True)
class RunCoverage:
    """Predicted uncertainty along a run, balance axes, the calibration's components."""

    components: tuple[str, ...]
    capacity: np.ndarray  # (n,) N / N·m
    loads: np.ndarray  # (S, n) N / N·m
    uncertainty: np.ndarray  # (S, n) N / N·m, k = 1; NaN where not computable
    outside: np.ndarray | None  # (S, n) bool; None: the calibration records no support
    sigma_pct_fs: Mapping[str, float]  # the calibration's σ
    model_name: str

    @property
    def uncertainty_pct_fs(self) -> np.ndarray:
        return self.uncertainty / self.capacity * 100.0

    def summary(self) -> dict:
        """coverage.json (interfaces.md): points, RMS and worst predicted u in % FS, the share of
        the run outside the support per component (null without a recorded support), the σ.
        """
        u = self.uncertainty_pct_fs
        finite = np.isfinite(u)
        rms, worst, outside = [], [], []
        for k in range(len(self.components)):
            values = u[finite[:, k], k]
            rms.append(float(np.sqrt(np.mean(values**2))) if values.size else None)
            worst.append(float(np.max(values)) if values.size else None)
            outside.append(None if self.outside is None else float(np.mean(self.outside[:, k])))
        return {
            'points': int(len(self.loads)),
            'predicted_u_pct_fs': dict(zip(self.components, _rounded(rms))),
            'worst_u_pct_fs': dict(zip(self.components, _rounded(worst))),
            'outside_support_fraction': dict(zip(self.components, _rounded(outside))),
            'sigma_pct_fs': {
                c: float(self.sigma_pct_fs[c]) for c in self.components if c in self.sigma_pct_fs
            },
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


def _extra_at_reference(model, rows: int) -> dict[str, np.ndarray] | None:
    """Variables besides the outputs that a model needs: at the reference temperature (dT = 0)
    and with each load last rising (dir = +1), for a run known only by its loads.
    """
    if not model.extra_variables:
        return None
    return {
        v: (np.ones(rows) if v.startswith('dir_') else np.zeros(rows))
        for v in model.extra_variables
    }


def outputs_for_run_loads(model, loads: np.ndarray) -> np.ndarray:
    """(S, n_inputs) the outputs, mV, that the wind-on form of `model` reads as loads (S, n); NaN
    rows for loads not finite or beyond LOADS_BEYOND_CAPACITY x capacity (checked by caller).
    """
    wind_on = model.without_constant()
    if getattr(model, 'form', 'direct') == 'iterative':
        return wind_on.outputs(loads)
    return outputs_for_loads(wind_on, loads, _extra_at_reference(model, len(loads)))


def _outside(
    calibration: Calibration,
    support: ScheduleSupport | None,
    loads: np.ndarray,
    outputs_mv: np.ndarray,
) -> np.ndarray | None:
    """(S, n) outside the support, or None when there is none to judge by."""
    if support is None or support.model not in calibration.models:
        return None
    base = calibration.models[support.model]
    pieces = covariance_and_sigma(base)
    if pieces is None or base.extra_variables or getattr(base, 'form', 'direct') != 'direct':
        return None
    finite = np.all(np.isfinite(outputs_mv), axis=1)
    load_leverage = np.full(len(loads), np.nan)
    load_leverage[finite] = leverage_of_rows(base.design(outputs_mv[finite]), pieces[0])
    return outside_support(support, loads, load_leverage)


def outside_support_of_outputs(
    calibration: Calibration,
    outputs_mv,
    *,
    model: str = 'adopted',
    support: ScheduleSupport | None = None,
) -> np.ndarray | None:
    """(S, n) True where the load `model` reads from bridge outputs (S, n_inputs), mV, zero
    subtracted, is outside the schedule's support for that component: what run_coverage judges,
    without the uncertainty (the live calibrator's /diagnostics). None: no support to judge by.
    """
    support = support if support is not None else recorded_support(calibration)
    if support is None:
        return None
    chosen = calibration.model(model)
    outputs_mv = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
    loads = chosen.without_constant().loads(
        outputs_mv, _extra_at_reference(chosen, len(outputs_mv))
    )
    return _outside(calibration, support, loads, outputs_mv)


def run_coverage(
    calibration: Calibration,
    loads=None,
    *,
    outputs_mv=None,
    model: str = 'adopted',
    support: ScheduleSupport | None = None,
) -> RunCoverage:
    """Predicted u (k = 1) and support at every load of a run.

    Parameters
    ----------
    calibration : the calibration; UncertaintyUnavailable if its model has no covariance.
    loads : (S, n) loads in N and N·m, balance axes, the calibration's components; or
    outputs_mv : (S, n_inputs) the bridge outputs of the run, mV, zero subtracted (the loads are
        then the model's reading of them).
    model : the calibration's model (default the adopted one).
    support : the schedule's support; default the one recorded in the calibration (refit
        records it; without one, or when its model is gone, RunCoverage.outside is None).
    """
    chosen = calibration.model(model)
    require_covariance(chosen)
    capacity = np.asarray(calibration.capacity, dtype=float)
    if outputs_mv is None:
        loads = np.atleast_2d(np.asarray(loads, dtype=float))
        reachable = np.all(np.isfinite(loads), axis=1) & np.all(
            np.abs(loads) <= LOADS_BEYOND_CAPACITY * capacity, axis=1
        )
        outputs_mv = np.full((len(loads), len(chosen.inputs)), np.nan)
        if reachable.any():
            outputs_mv[reachable] = outputs_for_run_loads(chosen, loads[reachable])
    else:
        outputs_mv = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
        loads = chosen.without_constant().loads(
            outputs_mv, _extra_at_reference(chosen, len(outputs_mv))
        )
    uncertainty = load_standard_uncertainty(
        chosen, outputs_mv, _extra_at_reference(chosen, len(loads)), loads=loads
    )
    support = support if support is not None else recorded_support(calibration)
    name = calibration.adopted if model in ('adopted', '') else model
    return RunCoverage(
        tuple(calibration.components),
        capacity,
        loads,
        uncertainty,
        _outside(calibration, support, loads, outputs_mv),
        dict(calibration.sigma_pct_fs),
        name,
    )


def summary_table(summary: dict, components) -> str:
    """coverage.json's numbers as a plain-text table (the coverage command's output, and the
    section of reduce's report.md).
    """
    computed = summary['not_computed']
    note = f' ({computed} not computed: not finite or beyond 2x capacity)' if computed else ''
    lines = [
        f'{summary["points"]} loads, model {summary["model"]}{note}',
        f'{"":22s}' + ''.join(f'{c:>9s}' for c in components),
    ]

    def row(label, values, fmt):
        cells = ['n/a' if values.get(c) is None else format(values[c], fmt) for c in components]
        return f'{label:22s}' + ''.join(f'{cell:>9s}' for cell in cells)

    lines.append(row('predicted u RMS, % FS', summary['predicted_u_pct_fs'], '.4f'))
    lines.append(row('predicted u max, % FS', summary['worst_u_pct_fs'], '.4f'))
    lines.append(row('calibration σ, % FS', summary['sigma_pct_fs'], '.4f'))
    lines.append(row('outside support', summary['outside_support_fraction'], '.1%'))
    if all(v is None for v in summary['outside_support_fraction'].values()):
        lines.append('the calibration records no schedule support (refit records it)')
    return '\n'.join(lines)
