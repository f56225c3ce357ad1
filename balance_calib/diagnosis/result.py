"""What a diagnosis returns (diagnose.py): the effects found and the Diagnosis value."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from ..config import CalibrationBody
from ..model.balance_model import BalanceModel
from ..tare.calibration_body import CorrectedData
from .lack_of_fit import LackOfFit


@dataclass(frozen=True)
class EffectFound:
    """One effect added to the model, with the numbers behind it (per component)."""

    name: str  # one of EFFECT_NAMES
    components: tuple[str, ...]
    evidence: str  # one line a person can check
    terms: tuple[str, ...]  # union over its components
    terms_by_component: Mapping[str, tuple[str, ...]]
    sigma_before_pct_fs: Mapping[str, float]  # in-sample, eq. (44), just before it was added
    sigma_after_pct_fs: Mapping[str, float]  # ... and just after
    press_sigma_before_pct_fs: Mapping[str, float]
    press_sigma_after_pct_fs: Mapping[str, float]
    removed_pct_fs: Mapping[str, float]  # sqrt(σ_before² - σ_after²): the size of the effect
    f_value: Mapping[str, float]  # partial F of its terms
    p_value: Mapping[str, float]  # of that F, Bonferroni-adjusted for the search
    correlation: Mapping[str, float]  # multiple r between residual and its terms
    evidence_by_component: Mapping[str, str]
    score: float  # BIC gain that ranked it
    nuisance: bool  # fitted at calibration, not applied live
    parameters: Mapping[str, float] = field(default_factory=dict)  # tare: the refitted body
    explaining_variable: Mapping[str, str] = field(default_factory=dict)  # per component
    explaining_values: Mapping[str, np.ndarray] = field(default_factory=dict)  # (N,) per component
    contribution: Mapping[str, np.ndarray] = field(default_factory=dict)  # (N,) load, N / N·m

    def to_report(self) -> dict:
        """The entry of report.json's "effects" list (interfaces.md)."""
        return {
            'name': self.name,
            'components': list(self.components),
            'evidence': self.evidence,
            'terms': list(self.terms),
            'sigma_after_pct_fs': {
                c: round(float(v), 4) for c, v in self.sigma_after_pct_fs.items()
            },
        }

    as_report = to_report  # the name refit/report.py calls


@dataclass(frozen=True)
class Diagnosis:
    """What the residuals say, and the model that answers it."""

    balance: str
    base_model: str
    components: tuple[str, ...]
    capacity: np.ndarray
    effects: tuple[EffectFound, ...]  # most important first
    sigma_pct_fs: Mapping[str, Mapping[str, float]]  # 'before' / 'after' -> component -> σ
    sigma_pct_fs_crossval: Mapping[str, Mapping[str, float]]
    base_fit: BalanceModel
    adopted: BalanceModel  # every term, nuisance included
    live: BalanceModel  # nuisance terms removed
    live_variables: tuple[str, ...]  # extra live inputs: 'dT', 'dir_FX', ...
    extra_variables: Mapping[str, np.ndarray]  # values per point the adopted fit used
    reference_temperature_c: float | None
    calibration_body: CalibrationBody
    body_source: str  # 'declared', 'estimated' or 'fitted'
    corrected: CorrectedData  # the data the adopted fit saw
    point_labels: np.ndarray
    times_s: np.ndarray
    orientation: np.ndarray
    load_direction: np.ndarray  # (N, 6) raw ±1 load history
    residuals_before: np.ndarray  # (N, 6) N / N·m, base model
    residuals_after: np.ndarray  # (N, 6) adopted model
    press_residuals_before: np.ndarray
    press_residuals_after: np.ndarray
    skipped: Mapping[str, str]  # effects not examined, and why
    unexplained: tuple = ()  # lack_of_fit.Unexplained entries
    repeatability_pct_fs: Mapping[str, float] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    lack_of_fit: LackOfFit | None = None  # the lack-of-fit numbers behind them
    # the tare outputs were re-read through the adopted model after the search (_retare): σ after
    # includes it, the effects' own σ before/after (taken when each was adopted) do not
    tare_reread: bool = False
    # (N, 6) residuals and leave-one-out residuals after the effects *named* on each component:
    # the adopted model plus the terms of the families the leftovers found only partly fitting
    # its structure (named in `unexplained`, not adopted); residuals_after where none was dropped
    # (the outliers gate judges a flagged point on them, gates/outliers.py)
    residuals_named: np.ndarray | None = None
    press_residuals_named: np.ndarray | None = None

    @property
    def points(self) -> int:
        return len(self.point_labels)

    @property
    def sigma_crossval_pct_fs(self) -> Mapping[str, Mapping[str, float]]:
        """Alias of sigma_pct_fs_crossval (the name FitSummary uses in refit/)."""
        return self.sigma_pct_fs_crossval

    @property
    def live_model(self) -> BalanceModel:
        return self.live

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)

    def residuals_pct_fs(self, which: str = 'after') -> np.ndarray:
        residuals = self.residuals_after if which == 'after' else self.residuals_before
        return residuals / self.capacity * 100.0

    def to_report(self) -> dict:
        """The σ and effect parts of report.json (interfaces.md)."""

        def rounded(table):
            return {k: {c: round(float(v), 4) for c, v in row.items()} for k, row in table.items()}

        return {
            'sigma_pct_fs': rounded(self.sigma_pct_fs),
            'sigma_pct_fs_crossval': rounded(self.sigma_pct_fs_crossval),
            'effects': [e.to_report() for e in self.effects],
            'unexplained': [u.to_report() for u in self.unexplained],
            'repeatability_pct_fs': {
                c: round(float(v), 4) for c, v in self.repeatability_pct_fs.items() if v == v
            },
            'warnings': list(self.warnings),
        }
