"""Loads of a sting-mounted model in a wind tunnel, from physics, for the coverage and design
tests.

A model on a sting over α -4...20°, β -6...6°, q∞ 5-15 kPa, its weight on top: normal force with
lift slope and vortex lift (C_N = C_Nα α + C_Nv sin α |sin α|), axial force with drag rise
(C_AF = C_A0 + k α² - C_N α·0.1), pitching moment about the balance centre from a moment-reference
centre ahead of it (C_m = C_m0 + C_mα α, plus x_r·N), side force with β, rolling moment with β
growing with α (dihedral effect), yawing moment with β and its transfer. Loads are made in
the tunnel axes of interfaces.md (normal force up, axial aft, pitching nose-up) and turned into
balance axes by the upright installation; each component is then scaled so that the envelope peaks
at a chosen fraction of the balance's capacity (30-70 %). None of this is a shape the calibration
models: the loads are products and sines of α, β and q, all six components at once.
"""

from __future__ import annotations

import numpy as np

from balance_calib.tunnel_axes import parse_installation

PEAK_FRACTION = np.array([0.35, 0.45, 0.70, 0.40, 0.60, 0.50])  # FX ... MZ, of capacity


def tunnel_loads(
    alpha_rad,
    beta_rad,
    q_pa,
    *,
    area_m2=0.012,
    chord_m=0.09,
    span_m=0.15,
    reference_x_m=0.03,
    weight_n=40.0,
    cg_x_m=0.01,
) -> np.ndarray:
    """(N, 6) air loads plus weight, tunnel axes: axial force aft, side force starboard, normal
    force up, rolling, pitching (nose up), yawing moment.
    """
    a, b, q = np.asarray(alpha_rad), np.asarray(beta_rad), np.asarray(q_pa)
    c_n = 2.8 * a + 1.6 * np.sin(a) * np.abs(np.sin(a))
    c_af = 0.025 + 0.35 * a**2 - 0.1 * c_n * a
    c_m = -0.04 - 0.55 * a - 0.3 * np.sin(a) * np.abs(np.sin(a))
    c_y = -0.9 * b - 0.4 * a * b
    c_l = -0.12 * b - 0.9 * a * b
    c_n_yaw = 0.10 * b + 0.05 * a * b
    qs = q * area_m2
    normal, axial, side = qs * c_n, qs * c_af, qs * c_y
    weight_normal, weight_axial = -weight_n * np.cos(a), weight_n * np.sin(a)
    pitch = qs * chord_m * c_m + reference_x_m * normal + cg_x_m * weight_normal
    roll = qs * span_m * c_l
    yaw = qs * span_m * c_n_yaw + reference_x_m * side
    return np.column_stack([axial + weight_axial, side, normal + weight_normal, roll, pitch, yaw])


def envelope(capacity, count: int, seed: int) -> np.ndarray:
    """(count, 6) balance-axis loads, N and N·m, of random attitudes and q∞ over the envelope;
    the same scale per component whatever the seed (fixed by a dense reference sweep).
    """
    capacity = np.asarray(capacity, float)
    upright = parse_installation('upright')
    grid = np.meshgrid(
        np.radians(np.linspace(-4, 20, 49)),
        np.radians(np.linspace(-6, 6, 25)),
        np.linspace(5e3, 15e3, 5),
        indexing='ij',
    )
    reference = upright.from_tunnel(tunnel_loads(*(g.ravel() for g in grid)))
    scale = PEAK_FRACTION * capacity / np.max(np.abs(reference), axis=0)
    rng = np.random.default_rng(seed)
    alpha = np.radians(rng.uniform(-4, 20, count))
    beta = np.radians(rng.uniform(-6, 6, count))
    q = rng.uniform(5e3, 15e3, count)
    return upright.from_tunnel(tunnel_loads(alpha, beta, q)) * scale
