"""Loads at the balance centre -> aerodynamic coefficients (TM-663 §10.3-10.4; interfaces.md).

For each sample or held point:

1. total load = reading - offsets (what the balance carries: air loads + weight);
2. attitude = support angles + deflection under the total load (deflection.py);
3. air load = total load - weight at that attitude (weight_tare.py; load space);
4. moments transferred to the moment reference centre: M' = M - r × F (body axes, axes.py);
5. body coefficients C_AF = F_X̄/(q∞S), C_Y, C_N, C_l = M_X̄'/(q∞Sb), C_m = M_Ȳ'/(q∞Sc), C_n =
M_Z̄'/(q∞Sb);
6. wind-axis forces and stability-axis moments (axes.py): C_D, C_Y,w, C_L, C_l,s, C_m,s, C_n,s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .axes import ALPHA, BETA, body_vectors, loads_from_body, wind_coefficients
from .model_file import ModelDescription
from .weight_tare import WeightTare


def transfer_moments(loads, moment_reference_centre_m) -> np.ndarray:
    """Loads (..., 6) about the balance centre -> about the moment reference centre r (3,), body
    axes: M' = M - r × F with F = (-F_X̄, F_Ȳ, -F_Z̄).
    """
    force, moment = body_vectors(loads)
    r = np.asarray(moment_reference_centre_m, float)
    return loads_from_body(force, moment - np.cross(np.broadcast_to(r, force.shape), force))


def coefficients_from_air_loads(air_loads, q_pa, model: ModelDescription) -> np.ndarray:
    """Air loads (..., 6) about the balance centre, q∞ (...,) Pa -> body coefficients (..., 6)."""
    about_mrc = transfer_moments(air_loads, model.moment_reference_centre_m)
    q = np.asarray(q_pa, float)[..., None]
    return about_mrc / (q * model.reference_area_m2 * model.reference_lengths_m)


def air_loads_from_coefficients(body_coefficients, q_pa, model: ModelDescription) -> np.ndarray:
    """The inverse: body coefficients (..., 6) -> air loads about the balance centre (..., 6)."""
    q = np.asarray(q_pa, float)[..., None]
    about_mrc = (
        np.asarray(body_coefficients, float)
        * q
        * model.reference_area_m2
        * model.reference_lengths_m
    )
    return transfer_moments(about_mrc, -np.asarray(model.moment_reference_centre_m, float))


@dataclass(frozen=True)
class Reduced:
    """Reduced samples or points: arrays over (...,)."""

    attitude: np.ndarray  # (..., 3) deflection-corrected (φ, α, β), rad
    q_pa: np.ndarray  # (...,)
    air_loads: np.ndarray  # (..., 6) about the balance centre, N, N·m
    body: np.ndarray  # (..., 6) C_AF, C_Y, C_N, C_l, C_m, C_n
    wind: np.ndarray  # (..., 6) C_D, C_Y,w, C_L, C_l,s, C_m,s, C_n,s

    @property
    def alpha_deg(self) -> np.ndarray:
        return np.degrees(self.attitude[..., ALPHA])

    @property
    def beta_deg(self) -> np.ndarray:
        return np.degrees(self.attitude[..., BETA])


def reduce_loads(
    readings, support_attitude, q_pa, model: ModelDescription, tare: WeightTare
) -> Reduced:
    """Calibrated readings (..., 6) (tunnel axes of §10.2, N, N·m), support angles (..., 3) rad and
    q∞ (...,) Pa -> coefficients. q∞ at or below zero gives NaN coefficients, never numbers.
    """
    total = np.asarray(readings, float) - tare.offsets
    attitude = model.deflection.corrected(support_attitude, total)
    air = total - tare.weight_loads(attitude)
    q = np.asarray(q_pa, float)
    q_safe = np.where(q > 0, q, np.nan)
    body = coefficients_from_air_loads(air, q_safe, model)
    wind = wind_coefficients(body, attitude[..., ALPHA], attitude[..., BETA])
    return Reduced(attitude, q, air, body, wind)
