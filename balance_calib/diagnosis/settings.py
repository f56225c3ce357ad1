"""The settings of one diagnosis (diagnose.py): levels, sizes and the families examined."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from .candidates import EFFECT_NAMES


@dataclass(frozen=True)
class DiagnosisSettings:
    alpha: float = 1e-4  # level of one family's test in a round (Bonferroni within it)
    min_effect_pct_fs: float = 0.01  # an effect must remove at least this RMS in a component
    max_rounds: int = 6
    max_terms: Mapping[str, int] = field(
        default_factory=lambda: {'cross_terms': 4, 'zero_drift': 8}
    )
    alpha_lack_of_fit: float = 0.001  # per component: residual beyond the repeatability
    # effects on a component with structure left over must explain this fraction of its excess
    # variance, or none is adopted
    min_explained: float = 0.75
    # per campaign: directed leftover tests (lack_of_fit.slow_structure_bases)
    alpha_slow_structure: float = 0.001
    # Chow test of a static family's coefficients (first vs second half)
    alpha_constancy: float = 1e-4
    # a runner-up within this fraction of the winner's score that the winner absorbs: "cannot be
    # separated" (a warning)
    equal_score: float = 0.8
    drift_oversampling: float = 2.0  # Fourier grid spacing = 1 / (oversampling x campaign span)
    # Weighted Bonferroni (small effects): a family's level α is split over its groups
    # in proportion to where a physical effect is expected, not flat; the levels still sum to α.
    # zero_drift: weight of frequency f ∝ f^-exponent (a random-walk zero: power ∝ f⁻²) x the
    # energy of its sine and cosine left after referring to the zero points and whitening (what
    # the test sees: the zero points remove the slow part, the red spectrum makes the fast part
    # small); the level goes to the frequencies just faster than the zero points follow.
    drift_spectrum_exponent: float = 2.0
    # temperature: shares of α for a component's own bridge first order (dT, dT·V_own: a zero and
    # a sensitivity linear in dT), own bridge second order (dT², dT²·V_own), and the other
    # bridges' dT·V, dT²·V (reaching the component only through the interactions)
    temperature_level_shares: tuple[float, float, float] = (0.5, 0.3, 0.2)
    tare_parameters: tuple[str, ...] = ('weight_n', 'cg_x_m')
    effects: tuple[str, ...] = EFFECT_NAMES

    def __post_init__(self):
        """Refuse settings outside their ranges, naming the setting (ValueError)."""

        def refuse(name, value, what):
            raise ValueError(f'DiagnosisSettings.{name} = {value!r}: must be {what}')

        for name in ('alpha', 'alpha_lack_of_fit', 'alpha_constancy'):
            value = getattr(self, name)
            if not 0.0 < value < 1.0:
                refuse(name, value, 'a level in (0, 1)')
        if not 0.0 <= self.alpha_slow_structure < 1.0:
            refuse('alpha_slow_structure', self.alpha_slow_structure, 'in [0, 1) (0: off)')
        for name in ('min_explained', 'equal_score'):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                refuse(name, value, 'a fraction in [0, 1]')
        if not (np.isfinite(self.min_effect_pct_fs) and self.min_effect_pct_fs >= 0):
            refuse('min_effect_pct_fs', self.min_effect_pct_fs, 'a finite % FS >= 0')
        if int(self.max_rounds) != self.max_rounds or self.max_rounds < 1:
            refuse('max_rounds', self.max_rounds, 'a whole number >= 1')
        if not (np.isfinite(self.drift_oversampling) and self.drift_oversampling > 0):
            refuse('drift_oversampling', self.drift_oversampling, 'finite and > 0')
        if not np.isfinite(self.drift_spectrum_exponent):
            refuse('drift_spectrum_exponent', self.drift_spectrum_exponent, 'finite')
        shares = np.asarray(self.temperature_level_shares, dtype=float)
        if shares.shape != (3,) or not np.all(np.isfinite(shares)) or np.any(shares < 0):
            refuse('temperature_level_shares', self.temperature_level_shares, '3 shares >= 0')
        if shares.sum() <= 0:
            refuse('temperature_level_shares', self.temperature_level_shares, 'not all zero')
        unknown = set(self.effects) - set(EFFECT_NAMES)
        if unknown:
            refuse('effects', self.effects, f'among {EFFECT_NAMES} (unknown: {sorted(unknown)})')
