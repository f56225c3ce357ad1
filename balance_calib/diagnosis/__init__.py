"""Residual diagnosis: find the physical effects the base model lacks and add them."""

from .candidates import EFFECT_NAMES
from .diagnose import diagnose, Diagnosis, DiagnosisSettings, EffectFound

__all__ = ['EFFECT_NAMES', 'Diagnosis', 'DiagnosisSettings', 'EffectFound', 'diagnose']
