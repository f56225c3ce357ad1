"""The axis conventions of the data reduction, and their signs: the one place they are written
down.

Loads (arrays (..., 6)) are what `/balance/wrench` carries in the tunnel axes of TM-663 §10.2
(Fig. 11.2), which the reduction uses as the model's body axes, origin at the balance centre:

    F_X̄  axial force, positive aft          M_X̄  rolling moment, positive right wing down
    F_Ȳ  side force, positive to starboard   M_Ȳ  pitching moment, positive nose up
    F_Z̄  normal force, positive up           M_Z̄  yawing moment, positive nose right

The vector algebra (moment transfer, gravity, rotations) is done in the right-handed body frame
x forward, y starboard, z down. There the force vector is F = (-F_X̄, F_Ȳ, -F_Z̄) and the moment
vector is M = (M_X̄, M_Ȳ, M_Z̄) unchanged (a positive rotation about x forward is right wing down,
about y starboard nose up, about z down nose right).

Attitudes (arrays (..., 3)) are ordered as on `/model/attitude`: (roll φ, angle of attack α,
sideslip β), rad. α positive nose up, β positive nose left (wind from starboard), φ positive right
wing down.

Gravity: the body is pitched by α and then rolled by φ relative to the tunnel (aircraft Euler
angles with θ = α); β turns the model about the tunnel vertical and leaves gravity's direction
alone. The unit gravity vector in body axes is g = (-sin α, sin φ cos α, cos φ cos α): upright at α
= 0 the weight pushes along +z (down) and reads as a negative normal force.

Wind axes: x_w along the free-stream velocity as seen from the model, z_w in the plane of symmetry,
down, y_w completing the right-handed set. In body axes

    x_w = ( cos α cos β,  sin β,  sin α cos β)
    y_w = (-cos α sin β,  cos β, -sin α sin β)
    z_w = (-sin α,        0,      cos α)

(stability axes: the same with β = 0). Drag is the force along -x_w, lift along -z_w, the wind-axis
side force along +y_w; so at α = β = 0 the wind axes are the body axes and C_D = C_AF, C_Y,w = C_Y,
C_L = C_N: drag and axial force both count positive aft, lift and normal force both positive up.
This reproduces interfaces.md: C_L = C_N cos α − C_AF sin α,
C_D = C_AF cos α cos β + C_N sin α cos β − C_Y sin β.
"""

from __future__ import annotations

import numpy as np

# signs that turn the load convention into body-frame vectors and back (an involution)
LOAD_TO_BODY_SIGNS = np.array([-1.0, 1.0, -1.0, 1.0, 1.0, 1.0])
COEFFICIENTS_BODY = ('CAF', 'CY', 'CN', 'Cl', 'Cm', 'Cn')
COEFFICIENTS_WIND = ('CD', 'CYw', 'CL', 'Cl_s', 'Cm_s', 'Cn_s')
ROLL, ALPHA, BETA = 0, 1, 2


def body_vectors(loads):
    """Loads (..., 6) in the §10.2 convention -> (force (..., 3), moment (..., 3)) in body axes."""
    vectors = np.asarray(loads, dtype=float) * LOAD_TO_BODY_SIGNS
    return vectors[..., :3], vectors[..., 3:]


def loads_from_body(force, moment) -> np.ndarray:
    """Body-axis force and moment vectors (..., 3) -> loads (..., 6) in the §10.2 convention."""
    force, moment = np.broadcast_arrays(np.asarray(force, float), np.asarray(moment, float))
    return np.concatenate([force, moment], axis=-1) * LOAD_TO_BODY_SIGNS


def gravity_direction(attitude) -> np.ndarray:
    """Unit gravity vector (..., 3) in body axes for attitudes (..., 3) = (φ, α, β) rad."""
    attitude = np.asarray(attitude, dtype=float)
    roll, alpha = attitude[..., ROLL], attitude[..., ALPHA]
    return np.stack(
        [-np.sin(alpha), np.sin(roll) * np.cos(alpha), np.cos(roll) * np.cos(alpha)], axis=-1
    )


def body_to_wind(alpha, beta) -> np.ndarray:
    """Rotation matrices (..., 3, 3) whose rows are x_w, y_w, z_w in body axes: v_wind = R @
    v_body.
    """
    alpha, beta = np.broadcast_arrays(np.asarray(alpha, float), np.asarray(beta, float))
    ca, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)
    zero = np.zeros_like(alpha)
    rows = [
        np.stack([ca * cb, sb, sa * cb], axis=-1),
        np.stack([-ca * sb, cb, -sa * sb], axis=-1),
        np.stack([-sa, zero, ca], axis=-1),
    ]
    return np.stack(rows, axis=-2)


def body_to_stability(alpha) -> np.ndarray:
    """Rotation matrices (..., 3, 3) body -> stability axes (wind axes with β = 0)."""
    return body_to_wind(alpha, np.zeros_like(np.asarray(alpha, float)))


def wind_coefficients(body_coefficients, alpha, beta) -> np.ndarray:
    """(..., 6) body coefficients (C_AF, C_Y, C_N, C_l, C_m, C_n) at α, β (rad) ->
    (C_D, C_Y,w, C_L, C_l,s, C_m,s, C_n,s): forces in wind axes, moments in stability axes.
    """
    force, moment = body_vectors(body_coefficients)  # same sign algebra as loads
    wind_force = np.einsum('...ij,...j->...i', body_to_wind(alpha, beta), force)
    stability_moment = np.einsum('...ij,...j->...i', body_to_stability(alpha), moment)
    # drag along -x_w and lift along -z_w: the load sign convention again
    return loads_from_body(wind_force, stability_moment)
