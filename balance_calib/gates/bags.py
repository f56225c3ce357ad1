"""The gates of a bag campaign, in the order a refit checks them (refit/pipeline.py): the data
and the sensitivities before the (slow) diagnosis, σ and outliers on the model to be adopted
after it (interfaces.md, report.json `acceptance`; AIAA R-091 practice checks a calibration
before it is used). Limits come from the balance config's `acceptance:` mapping (limits.py);
each gate gives one line a person can act on and raises nothing: the pipeline decides (RefitError,
unless forced).
"""

from __future__ import annotations

from typing import Mapping

from ..config import BalanceConfig, LoadSchedule
from ..fit.crossval import press_residuals
from .campaign import body_gate, capacity_gate, marker_gate, zero_gate
from .fit_quality import sigma_gate
from .gate import Gate, ModelResiduals
from .limits import acceptance_limits, AcceptanceLimits
from .outlier_gates import bag_outlier_gate
from .outputs import clipping_gate
from .schedule import schedule_gate
from .sensitivity import active_gate, sensitivity_gate


def data_gates(
    config: BalanceConfig,
    points,
    reduction,
    fits,
    cut=None,
    active=None,
    limits: AcceptanceLimits | None = None,
    schedule: LoadSchedule | None = None,
) -> list[Gate]:
    """Gates on the data and the sensitivities, before the (slow) diagnosis. points: LoadPoints;
    fits: order -> ModelFit; cut: load_points.CutSummary or None; active: Calibration or None;
    schedule: the one the campaign ran (None: the balance config's own).
    """
    limits = limits or acceptance_limits(config)
    gates = [
        sensitivity_gate(config, fits, limits),
        schedule_gate(
            config, points, schedule if schedule is not None else config.schedule, limits
        ),
    ]
    if active is not None:
        gates.append(active_gate(config, fits, active, limits))
    gates += [
        zero_gate(config, points, limits),
        body_gate(config, reduction, limits),
        capacity_gate(config, points, limits),
    ]
    if cut is not None:
        gates += [clipping_gate(cut), marker_gate(cut)]
    return gates


def fit_gates(
    config: BalanceConfig,
    points,
    model: ModelResiduals,
    limits: AcceptanceLimits | None = None,
    unexplained: Mapping[str, str] | None = None,
    structure=None,
) -> list[Gate]:
    """σ and outlier gates on the model to be adopted (ModelResiduals: its σ, residuals and
    leave-one-out residuals). unexplained: component -> what the diagnosis's unexplained
    structure there tracks (the outlier gate then names it as a cause besides a weight or marker
    error). structure: diagnosis.coherence.CampaignStructure or None; a flagged point that the
    campaign's structure on a component the diagnosis found something on predicts from the other
    points is not an outlier (it is reported as explained; outliers.py).
    """
    limits = limits or acceptance_limits(config)
    return [
        sigma_gate(config, model.sigma_pct_fs, limits, model.what),
        bag_outlier_gate(config, points, model, limits, unexplained or {}, structure),
    ]


def base_model_residuals(reduction, base_fit) -> ModelResiduals:
    """The base model's σ, residuals and leave-one-out residuals on the corrected data."""
    design = base_fit.fit.model.design(reduction.corrected.bridge_outputs_mv)
    return ModelResiduals(
        base_fit.sigma_pct_fs,
        base_fit.fit.residuals,
        press_residuals(design, base_fit.fit.residuals),
    )
