"""The model's weight tare by attitude, in load space.

What the balance reads wind-off at attitude a = (φ, α, β) is its constant offset plus the model's
weight W acting at its centre of gravity r_cg (axes.py for the conventions):

    F = W g(a),   M = r_cg × F = (W r_cg) × g(a),   reading = loads(F, M) + offset

Linear in p = (W, W·x_cg, W·y_cg, W·z_cg) and the six offsets, so a wind-off attitude sweep over
α and φ gives all ten by least squares - the idea of the calibration body's eqs. (29)-(31) of
TM-663, now over the model's attitudes instead of the calibration body's orientations. Rows are
weighted by the load σ of a held point, columns scaled, solved by SVD (numpy lstsq); a sweep that
leaves a parameter undetermined (e.g. no rolled attitude: y_cg, z_cg and the offsets trade) is
refused with the parameter named.

The tare is subtracted in load space: the calibration is evaluated on the full bridge outputs
(wind-on or wind-off) and these loads are subtracted afterwards. Subtracting wind-off outputs from
wind-on outputs before the calibration is wrong for a nonlinear balance: model(V_on) - model(V_off)
differs from model(V_on - V_off) by the cross terms between air loads and weight.

The attitude at which the weight acts is the deflected one, which depends on the loads, which
depend on the offsets: the fit iterates offsets -> attitudes -> fit until nothing changes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..fit.svd import scaled_svd
from .axes import gravity_direction, loads_from_body
from .deflection import Deflection

PARAMETERS = (
    'W',
    'W*x_cg',
    'W*y_cg',
    'W*z_cg',
    'offset_FX',
    'offset_FY',
    'offset_FZ',
    'offset_MX',
    'offset_MY',
    'offset_MZ',
)


class WeightTareError(ValueError):
    """A wind-off sweep that cannot give the weight tare; the message says what is missing."""


def gravity_basis(attitude) -> np.ndarray:
    """(..., 6, 4): the loads read per unit of (W, W·x_cg, W·y_cg, W·z_cg) at attitudes (...,
    3).
    """
    g = gravity_direction(attitude)
    zero = np.zeros_like(g)
    columns = [loads_from_body(g, zero)]
    for axis in range(3):
        unit = np.zeros(3)
        unit[axis] = 1.0
        columns.append(loads_from_body(zero, np.cross(unit, g)))  # (W r) x g, one component of W r
    return np.stack(columns, axis=-1)


def weight_loads(attitude, weight_n: float, cg_m) -> np.ndarray:
    """Loads (..., 6) of the model's weight at attitudes (..., 3), about the balance centre."""
    p = np.concatenate([[weight_n], weight_n * np.asarray(cg_m, float)])
    return gravity_basis(attitude) @ p


@dataclass(frozen=True)
class WeightTare:
    """Weight, centre of gravity and offsets: what the balance reads wind-off at any attitude."""

    weight_n: float
    cg_m: np.ndarray  # (3,) body axes from the balance centre
    offsets: np.ndarray  # (6,) N, N·m: the reading with nothing on the balance
    # (10, 10) of (W, W·cg, offsets) in PARAMETERS order; zeros where declared
    covariance: np.ndarray
    source: str  # 'estimated' | 'declared'
    points: int = 0  # wind-off held points it came from
    residual_rms: np.ndarray | None = None  # (6,) rms of the fit residuals per component

    @property
    def parameters(self) -> np.ndarray:
        return np.concatenate([[self.weight_n], self.weight_n * self.cg_m, self.offsets])

    def weight_loads(self, attitude) -> np.ndarray:
        return weight_loads(attitude, self.weight_n, self.cg_m)

    def reading(self, attitude) -> np.ndarray:
        """What the balance reads wind-off at attitudes (..., 3): weight loads + offsets."""
        return self.weight_loads(attitude) + self.offsets

    def design(self, attitude) -> np.ndarray:
        """(..., 6, 10): d reading / d parameters, for propagating the covariance."""
        basis = gravity_basis(attitude)
        eye = np.broadcast_to(np.eye(6), basis.shape[:-2] + (6, 6))
        return np.concatenate([basis, eye], axis=-1)

    @property
    def cg_sigma_m(self) -> np.ndarray:
        """(3,) standard uncertainty of the CG (first order, from the covariance of W and W·cg)."""
        p, c = self.parameters[:4], self.covariance[:4, :4]
        jac = np.zeros((3, 4))
        jac[:, 0] = -p[1:] / p[0] ** 2
        jac[:, 1:] = np.eye(3) / p[0]
        return np.sqrt(np.maximum(np.diag(jac @ c @ jac.T), 0.0))

    @property
    def weight_sigma_n(self) -> float:
        return float(np.sqrt(max(self.covariance[0, 0], 0.0)))


def declared_tare(weight_n: float, cg_m, offsets=np.zeros(6)) -> WeightTare:
    return WeightTare(
        float(weight_n),
        np.asarray(cg_m, float),
        np.asarray(offsets, float),
        np.zeros((10, 10)),
        'declared',
    )


def _parametrisation(weight_n, cg_m):
    """P = p0 + P u for (W, W·cg) given what is declared: (p0 (4,), P (4, k), names of u)."""
    if weight_n is not None and cg_m is not None:
        return (
            np.concatenate([[weight_n], weight_n * np.asarray(cg_m, float)]),
            np.zeros((4, 0)),
            [],
        )
    if weight_n is not None:
        return (
            np.array([weight_n, 0.0, 0.0, 0.0]),
            np.vstack([np.zeros(3), np.eye(3)]),
            ['x_cg', 'y_cg', 'z_cg'],
        )
    if cg_m is not None:
        return np.zeros(4), np.concatenate([[1.0], np.asarray(cg_m, float)])[:, None], ['weight']
    return np.zeros(4), np.eye(4), ['weight', 'x_cg', 'y_cg', 'z_cg']


def fit_weight_tare(
    readings,
    support_attitude,
    *,
    sigma_loads,
    deflection: Deflection = Deflection(),
    weight_n: float | None = None,
    cg_m=None,
    max_iterations: int = 50,
) -> WeightTare:
    """Weight tare from wind-off held points.

    readings (K, 6): mean loads of each wind-off hold, N / N·m (calibration on the full outputs);
    support_attitude (K, 3): mean support angles (φ, α, β), rad; sigma_loads (6,): σ of a held
    point's mean load per component (weights the rows and gives the covariance).
    weight_n / cg_m: declared values (None: estimate). Offsets are always fitted.
    """
    readings = np.atleast_2d(np.asarray(readings, float))
    support = np.atleast_2d(np.asarray(support_attitude, float))
    sigma = np.asarray(sigma_loads, float)
    if readings.shape[1:] != (6,) or support.shape != (len(readings), 3):
        raise ValueError('readings (K, 6) and support_attitude (K, 3) must have the same K')
    if not (np.all(np.isfinite(readings)) and np.all(np.isfinite(support))):
        raise WeightTareError('a wind-off held point has NaN loads or attitude')
    if np.any(~np.isfinite(sigma)) or np.any(sigma <= 0):
        raise ValueError(f'sigma_loads must be positive and finite, not {sigma}')
    p0, embed, unknown_names = _parametrisation(weight_n, cg_m)
    k = embed.shape[1]
    names = unknown_names + [f'offset of {c}' for c in ('F_X', 'F_Y', 'F_Z', 'M_X', 'M_Y', 'M_Z')]
    if len(readings) * 6 < k + 6:
        raise WeightTareError(
            f'{len(readings)} wind-off held point(s) cannot determine {k + 6} tare parameters'
        )
    offsets = np.zeros(6)
    previous = None
    for _ in range(max_iterations):
        attitude = deflection.corrected(support, readings - offsets)
        basis = gravity_basis(attitude)  # (K, 6, 4)
        design = np.concatenate(
            [basis @ embed, np.broadcast_to(np.eye(6), (len(readings), 6, 6))], axis=-1
        )
        target = readings - basis @ p0
        a = (design / sigma[None, :, None]).reshape(-1, k + 6)
        b = (target / sigma).ravel()
        u, s, vt, scale = scaled_svd(a)
        if s[-1] <= 1e-9 * s[0]:
            weakest = int(np.argmax(np.abs(vt[-1])))
            raise WeightTareError(
                f'the wind-off sweep ({len(readings)} held points) does not determine the '
                f'{names[weakest]}: add attitudes (other α, rolled φ) or declare it in the '
                'model file'
            )
        solution = (vt.T @ ((u.T @ b) / s)) / scale
        offsets = solution[k:]
        if previous is not None and np.max(np.abs(solution - previous)) <= 1e-12 * (
            1 + np.max(np.abs(solution))
        ):
            break
        previous = solution
    covariance_u = (vt.T / s**2) @ vt / np.outer(scale, scale)
    full = np.zeros((10, k + 6))
    full[:4, :k] = embed
    full[4:, k:] = np.eye(6)
    covariance = full @ covariance_u @ full.T
    p = p0 + embed @ solution[:k]
    residual = target - design @ solution
    return WeightTare(
        float(p[0]),
        p[1:] / p[0],
        offsets.copy(),
        covariance,
        'declared' if k == 0 else 'estimated',
        len(readings),
        np.sqrt(np.mean(residual**2, axis=0)),
    )


# A declared weight or CG further than this many standard uncertainties of the sweep's own estimate
# contradicts the sweep (3σ: a false alarm in about 1 run of 100 for four parameters).
CONTRADICTION_SIGMAS = 3.0


def declared_weight_contradiction(
    readings,
    support_attitude,
    *,
    sigma_loads,
    deflection: Deflection = Deflection(),
    weight_n: float | None,
    cg_m,
    model_name: str = 'the model file',
) -> str:
    """One line when the wind-off sweep's own estimate of the weight or centre of gravity
    contradicts the declared ones (beyond CONTRADICTION_SIGMAS of the estimate's uncertainty), ''
    when it agrees, nothing is declared, or the sweep cannot estimate what is declared.

    A declared weight is used as given (fit_weight_tare): a model file of another model (40 N
    declared, 250 N on the balance) leaves the difference in every wind-on point, silently.
    Arguments as fit_weight_tare's.
    """
    if weight_n is None and cg_m is None:
        return ''
    estimate = None
    held: dict[str, Any] = {}
    # all four free; else what the sweep can estimate with the other held at its declared value
    for held in ({}, {'cg_m': cg_m}, {'weight_n': weight_n}):
        if any(v is None for v in held.values()):
            continue
        try:
            estimate = fit_weight_tare(
                readings, support_attitude, sigma_loads=sigma_loads, deflection=deflection, **held
            )
        except WeightTareError:
            continue
        break
    if estimate is None:
        return ''
    off = []  # what is held at its declared value is no evidence
    if weight_n is not None and 'weight_n' not in held:
        if abs(estimate.weight_n - weight_n) > CONTRADICTION_SIGMAS * estimate.weight_sigma_n:
            off.append('weight')
    if cg_m is not None and 'cg_m' not in held:
        difference = np.abs(estimate.cg_m - np.asarray(cg_m, float))
        off += [
            f'{axis}_cg'
            for axis, d, u in zip('xyz', difference, estimate.cg_sigma_m)
            if d > CONTRADICTION_SIGMAS * u
        ]
    if not off:
        return ''
    declared_cg = '' if cg_m is None else f' at ({", ".join(f"{1000 * c:.1f}" for c in cg_m)}) mm'
    declared_w = 'its weight' if weight_n is None else f'{weight_n:g} N'
    return (
        f'the wind-off sweep ({len(np.atleast_2d(readings))} held points) gives W = '
        f'{estimate.weight_n:.4g} ± {estimate.weight_sigma_n:.2g} N at '
        f'({", ".join(f"{1000 * c:.1f}" for c in estimate.cg_m)}) ± '
        f'({", ".join(f"{1000 * c:.1f}" for c in estimate.cg_sigma_m)}) mm; {model_name} declares '
        f'{declared_w}{declared_cg}: {", ".join(off)} beyond {CONTRADICTION_SIGMAS:g}σ; is it '
        "the model that was run? (--estimate-weight takes the sweep's)"
    )
