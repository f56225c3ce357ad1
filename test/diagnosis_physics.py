"""Effects written from their physics, for the diagnosis tests (not from the terms of
balance_calib/diagnosis/candidates.py, and not from the shapes of simulation/effects.py).

Hysteresis loops
    preisach   a Preisach loop: a field of relay hysterons, each switching up at α and down at
               β ≤ α on the bridge's output over its rated output, weighted by a Gaussian in
               (α - β, α + β); the widest loop is at zero and narrows towards the extremes
    bouc_wen   a Bouc-Wen loop (a smooth, rate-independent loop of a structural joint): the
               offset z follows dz = du - β|du||z|^(n-1)z - γ du|z|^n on the bridge's output u,
               saturating within `knee` of travel after each reversal
    masing     a Masing (Iwan) loop with memory: a tanh backbone, each branch from a turning point
               the backbone scaled by two, inner loops closing where they started
    reseating  a joint that re-seats at every reversal: Masing branches without memory, the slip
               saturating at full slip; its offset ratchets with the small reversals
    ratchet    the same joint whose slip does not saturate (ratcheting: slip accumulating with
               every unequal cycle), outside every family
    friction   friction in the loading path: the load reaching the balance falls short of the
               applied one by μ |L| while the weights rise and exceeds it while they fall, with a
               stick band (the pulley turns only once the rope's tension has changed by 2δ)
Sign asymmetries (the response to +L and -L of equal magnitude differ)
    sign_step  the sensitivity steps at zero load (a gap closing, a preload lost), smoothed over
               3 % of capacity
    negative_curvature  a curvature |x|^2.5 on negative loads only (a flexure buckling in
               compression)
Others
    lagged_temperature  zero and sensitivity of one bridge following the balance temperature
               through a 20 min thermal lag
    power_creep  output creeping after each load change as a power law of the time since it
               (log-like, no single time constant)

Each effect is an `Effect` of the simulator (it gets the sample context, returns the outputs).
`scaled(...)` sizes one so that it adds `floors` x Table 17's cubic σ (RMS) to a component's
cubic-fit residual, measured on the noise-free campaign, the size convention of
simulation/diagnosis_rates.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from balance_calib.config import load_balance_config
from balance_calib.diagnosis.statistics import fit_columns
from balance_calib.model.terms import as_variables, design_matrix
from balance_calib.model.tm663 import tm663_terms
from balance_calib.simulation.diagnosis_rates import noise_floor_pct_fs, simulate_reduction
from balance_calib.simulation.effects import Effect

COMPONENTS = ('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ')


def _where(bridges, n=6) -> np.ndarray:
    """(6,) 0/1 mask of the bridges an effect acts on: 'all' or a component name or index."""
    mask = np.zeros(n)
    if bridges == 'all':
        mask[:] = 1.0
    else:
        mask[COMPONENTS.index(bridges) if isinstance(bridges, str) else int(bridges)] = 1.0
    return mask


@dataclass(frozen=True)
class PreisachLoop(Effect):
    size: float = 0.0  # offset of a fully switched field, x rated output
    bridges: str = 'all'
    spread: float = 0.35  # Gaussian width of the hysterons' switching half-gap
    name = 'preisach'

    def outputs(self, outputs_mv, ctx):
        grid = np.linspace(-1.2, 1.2, 25)
        alpha, beta = np.meshgrid(grid, grid, indexing='ij')
        keep = alpha > beta
        alpha, beta = alpha[keep], beta[keep]
        weight = np.exp(
            -0.5 * ((alpha - beta) / 2 / self.spread) ** 2 - 0.5 * ((alpha + beta) / 1.0) ** 2
        )
        weight /= weight.sum()
        u = ctx.outputs_mv / ctx.rated_output_mv  # (S, 6)
        state = np.where(alpha + beta < 0, 1.0, -1.0)[None, :].repeat(6, axis=0)  # demagnetised
        offset = np.empty_like(u)
        for i, row in enumerate(u):
            state = np.where(row[:, None] >= alpha[None, :], 1.0, state)
            state = np.where(row[:, None] <= beta[None, :], -1.0, state)
            offset[i] = state @ weight
        return outputs_mv + self.size * ctx.rated_output_mv * _where(self.bridges) * offset


@dataclass(frozen=True)
class BoucWenLoop(Effect):
    size: float = 0.0  # offset at saturation, x rated output
    bridges: str = 'all'
    knee: float = 0.15  # travel (x rated output) over which the offset saturates
    exponent: float = 1.0
    name = 'bouc_wen'

    def outputs(self, outputs_mv, ctx):
        # dz = A du - β |du| |z|^(n-1) z - γ du |z|^n with A = 1, β = γ = 1 / (2 knee^n): z
        # saturates at ±knee; integrated in small steps of u (the offset is size x z / knee)
        u = ctx.outputs_mv / ctx.rated_output_mv
        n = self.exponent
        beta = gamma = 1.0 / (2.0 * self.knee**n)
        z = np.zeros(u.shape[1])
        out = np.empty_like(u)
        previous = u[0].copy()
        for i, row in enumerate(u):
            travel = row - previous
            steps = max(1, int(np.ceil(np.max(np.abs(travel)) / (0.02 * self.knee))))
            du = travel / steps
            for _ in range(steps):
                z = (
                    z
                    + du
                    - beta * np.abs(du) * np.abs(z) ** (n - 1) * z
                    - gamma * du * np.abs(z) ** n
                )
            out[i] = z
            previous = row
        return (
            outputs_mv + self.size * ctx.rated_output_mv * _where(self.bridges) * out / self.knee
        )


def _masing(u: np.ndarray, backbone) -> np.ndarray:
    """Masing's rules with memory (the Iwan model of joints slipping one after another) on one
    series u (S,): the virgin curve is the backbone f; after a reversal at (u_r, y_r) the branch
    is y_r + 2 f((u - u_r) / 2); a branch that reaches the turning point it started from closes
    that inner loop and the response continues on the branch it interrupted (or the backbone).
    """
    y = np.empty_like(u)
    stack = []  # turning points (u_r, y_r), oldest first
    going, previous, current = 0.0, u[0], float(backbone(u[0]))
    for i, x in enumerate(u):
        step = np.sign(x - previous)
        if step != 0 and going != 0 and step != going:
            stack.append((previous, current))
        if step != 0:
            going = step
        # close inner loops: passing the turning point before the last one resumes its branch
        while len(stack) >= 2 and (x - stack[-2][0]) * going >= 0:
            stack.pop()
            stack.pop()
        if len(stack) == 1 and (x - (-stack[0][0])) * going >= 0 and abs(x) >= abs(stack[0][0]):
            stack.pop()  # beyond the largest excursion: the backbone again
        if stack:
            u_r, y_r = stack[-1]
            current = y_r + 2.0 * float(backbone((x - u_r) / 2.0))
        else:
            current = float(backbone(x))
        y[i] = current
        previous = x
    return y


@dataclass(frozen=True)
class MasingLoop(Effect):
    size: float = 0.0  # backbone saturation, x rated output
    bridges: str = 'all'
    knee: float = 0.3  # backbone tanh scale, x rated output
    name = 'masing'

    def outputs(self, outputs_mv, ctx):
        u = ctx.outputs_mv / ctx.rated_output_mv
        backbone = lambda x: np.tanh(x / self.knee)  # noqa: E731
        mask = _where(self.bridges)
        loop = np.zeros_like(u)
        for j in np.flatnonzero(mask):
            # the loop only: the mean response is the backbone, which the cubic takes
            loop[:, j] = _masing(u[:, j], backbone) - backbone(u[:, j])
        return outputs_mv + self.size * ctx.rated_output_mv * loop


@dataclass(frozen=True)
class ReseatingJoint(Effect):
    """A joint that re-seats at every reversal and so forgets the earlier cycles: each branch is
    the doubled tanh backbone from the last turning point, no inner loop closes, and the slip
    saturates at full slip (|y| <= 1): the offset ratchets with the history of small reversals.
    """

    size: float = 0.0  # full slip, x rated output
    bridges: str = 'all'
    knee: float = 0.3
    saturate: bool = True  # False: the slip accumulates without bound (ratcheting)
    name = 'reseating'

    def outputs(self, outputs_mv, ctx):
        u = ctx.outputs_mv / ctx.rated_output_mv
        backbone = lambda x: np.tanh(x / self.knee)  # noqa: E731
        y = np.empty_like(u)
        turn_u, turn_y, going = np.zeros(u.shape[1]), np.zeros(u.shape[1]), np.zeros(u.shape[1])
        virgin = np.ones(u.shape[1], bool)
        previous = u[0].copy()
        for i, row in enumerate(u):
            step = np.sign(row - previous)
            reversal = (step != 0) & (going != 0) & (step != going)
            turn_u = np.where(reversal, previous, turn_u)
            turn_y = np.where(reversal, y[i - 1] if i else 0.0, turn_y)
            virgin &= ~reversal
            going = np.where(step != 0, step, going)
            branch = turn_y + 2.0 * backbone((row - turn_u) / 2.0)
            branch = np.clip(branch, -1.0, 1.0) if self.saturate else branch
            y[i] = np.where(virgin, backbone(row), branch)
            previous = row
        loop = (y - backbone(u)) * _where(self.bridges)
        return outputs_mv + self.size * ctx.rated_output_mv * loop


@dataclass(frozen=True)
class LoadPathFriction(Effect):
    friction: float = 0.0  # μ: the fraction of the load lost to friction while moving
    bridges: str = 'all'
    stick: float = 0.04  # δ: half the stick band, x capacity
    name = 'friction'

    def outputs(self, outputs_mv, ctx):
        x = ctx.loads / ctx.capacity
        z = np.empty_like(x)  # -1 falling ... +1 rising
        anchor = x[0].copy()
        for i, row in enumerate(x):
            anchor = np.clip(anchor, row - self.stick, row + self.stick)
            z[i] = (row - anchor) / self.stick
        lost = self.friction * np.abs(x) * z  # of capacity, per component
        return outputs_mv - ctx.rated_output_mv * _where(self.bridges) * lost


@dataclass(frozen=True)
class SensitivityStep(Effect):
    step: float = 0.0  # relative sensitivity change for negative loads
    bridges: str = 'all'
    width: float = 0.03  # smoothing, x capacity
    name = 'sign_step'

    def outputs(self, outputs_mv, ctx):
        x = ctx.loads / ctx.capacity
        negative = 1.0 / (1.0 + np.exp(x / self.width))
        return outputs_mv + self.step * ctx.rated_output_mv * _where(self.bridges) * x * negative


@dataclass(frozen=True)
class NegativeCurvature(Effect):
    curvature: float = 0.0  # x rated output at -capacity
    bridges: str = 'all'
    name = 'negative_curvature'

    def outputs(self, outputs_mv, ctx):
        x = ctx.loads / ctx.capacity
        bend = np.where(x < 0, np.abs(x) ** 2.5, 0.0)
        return outputs_mv + self.curvature * ctx.rated_output_mv * _where(self.bridges) * bend


@dataclass(frozen=True)
class LaggedTemperature(Effect):
    zero: float = 0.0  # x rated output per kelvin
    bridges: str = 'FX'
    lag_s: float = 1200.0
    name = 'lagged_temperature'

    def outputs(self, outputs_mv, ctx):
        t, temperature = ctx.times_s, ctx.temperature_c
        gauge = np.empty_like(temperature)
        gauge[0] = temperature[0]
        for i in range(1, len(t)):
            a = 1.0 - np.exp(-(t[i] - t[i - 1]) / self.lag_s)
            gauge[i] = gauge[i - 1] + a * (temperature[i] - gauge[i - 1])
        d = (gauge - ctx.reference_temperature_c)[:, None]
        # zero shift and a sensitivity change a tenth of it per kelvin (gauge factor vs
        # temperature)
        shift = self.zero * ctx.rated_output_mv * d + 0.1 * self.zero * d * ctx.outputs_mv
        return outputs_mv + _where(self.bridges) * shift


@dataclass(frozen=True)
class PowerCreep(Effect):
    creep: float = 0.0  # relative output gained 1 h after a load change
    bridges: str = 'FX'
    onset_s: float = 10.0
    exponent: float = 0.3
    name = 'power_creep'

    def outputs(self, outputs_mv, ctx):
        v, t = ctx.outputs_mv, ctx.times_s
        change = np.vstack([v[:1] * 0.0, np.diff(v, axis=0)])
        steps = np.flatnonzero(np.any(np.abs(change) > 1e-9, axis=1))
        gained = np.zeros_like(v)
        unit = ((3600.0 + self.onset_s) / self.onset_s) ** self.exponent - 1.0
        for j in steps:
            after = slice(j, None)
            growth = ((t[after] - t[j] + self.onset_s) / self.onset_s) ** self.exponent - 1.0
            gained[after] += change[j] * (growth / unit)[:, None]
        return outputs_mv + self.creep * _where(self.bridges) * gained


SHAPES = {
    'preisach': (PreisachLoop, 'size'),
    'bouc_wen': (BoucWenLoop, 'size'),
    'masing': (MasingLoop, 'size'),
    'reseating': (ReseatingJoint, 'size'),
    'friction': (LoadPathFriction, 'friction'),
    'sign_step': (SensitivityStep, 'step'),
    'negative_curvature': (NegativeCurvature, 'curvature'),
    'lagged_temperature': (LaggedTemperature, 'zero'),
    'power_creep': (PowerCreep, 'creep'),
}
FAMILY = {
    'preisach': 'hysteresis',
    'bouc_wen': 'hysteresis',
    'masing': 'hysteresis',
    'reseating': 'hysteresis',
    'friction': 'hysteresis',
    'sign_step': 'bidirectional',
    'negative_curvature': 'bidirectional',
    'lagged_temperature': 'temperature',
    'power_creep': 'creep',
}


def make(shape: str, size: float, bridges: str) -> Effect:
    if shape == 'ratchet':  # the re-seating joint whose slip never saturates
        return ReseatingJoint(size=size, bridges=bridges, saturate=False)
    cls, parameter = SHAPES[shape]
    return cls(**{parameter: size, 'bridges': bridges})


def cubic_residuals(config, reduction) -> np.ndarray:
    """(P, 6) residuals of a plain cubic fit of each component, N / N·m."""
    terms = tm663_terms('cubic', config.bridge_outputs)
    outputs = reduction.corrected.bridge_outputs_mv
    design = design_matrix(terms, as_variables(config.bridge_outputs, outputs), len(outputs))
    return np.column_stack(
        [
            fit_columns(design, reduction.corrected.loads[:, k]).residuals
            for k in range(len(config.components))
        ]
    )


@lru_cache(maxsize=None)
def _clean_residuals(balance: str) -> np.ndarray:
    config = load_balance_config(balance)
    return cubic_residuals(config, simulate_reduction(config, noise_scale=0.0))


def added_rms_pct_fs(balance: str, effects) -> np.ndarray:
    """(6,) RMS (% FS) the effects add to each component's cubic residual, noise-free."""
    config = load_balance_config(balance)
    dirty = cubic_residuals(config, simulate_reduction(config, list(effects), noise_scale=0.0))
    return (
        np.sqrt(np.mean((dirty - _clean_residuals(balance)) ** 2, axis=0))
        / config.capacity
        * 100.0
    )


@lru_cache(maxsize=None)
def scaled_size(
    balance: str, shape: str, bridges: str, component: str | None, floors: float = 1.0
) -> float:
    """The size parameter of `shape` adding `floors` x the cubic σ floor to `component` (None:
    on average over the six components, for an effect on every bridge).
    """
    config = load_balance_config(balance)
    floor = noise_floor_pct_fs(config)
    size = 1e-3
    for _ in range(4):  # the sizes are near-linear in the parameter
        added = added_rms_pct_fs(balance, [make(shape, size, bridges)]) / floor
        got = (
            float(np.mean(added))
            if component is None
            else float(added[config.components.index(component)])
        )
        if got <= 0:
            break
        size *= floors / got
        if abs(got / floors - 1.0) < 0.03:
            break
    return float(size)


def scaled(
    balance: str, shape: str, bridges: str, component: str | None = None, floors: float = 1.0
) -> Effect:
    """`shape` on `bridges` ('all' or one component), `floors` x the floor on `component`
    (default: the bridge's own; for 'all', on average over the components).
    """
    if component is None and bridges != 'all':
        component = bridges
    return make(shape, scaled_size(balance, shape, bridges, component, floors), bridges)


def widest_loop(shape: str) -> float:
    """Widest |rising - falling| branch difference (x rated output) of `shape` at size 1 over a
    major cycle 0 -> +rated -> -rated -> +rated: the size that gives a loop w wide is w / this.
    """
    from types import SimpleNamespace

    u = np.concatenate([np.linspace(0, 1, 101), np.linspace(1, -1, 201), np.linspace(-1, 1, 201)])
    v = np.repeat(u[:, None], 6, axis=1)
    ctx = SimpleNamespace(outputs_mv=v, rated_output_mv=np.ones(6), loads=v, capacity=np.ones(6))
    offset = make(shape, 1.0, 'all').outputs(np.zeros_like(v), ctx)[:, 0]
    falling, rising = offset[101:302][::-1], offset[302:]
    return float(np.max(np.abs(rising - falling)))


def loop_of_width(shape: str, width: float, bridges: str = 'all') -> Effect:
    """A loop `width` x rated output wide at its widest."""
    return make(shape, width / widest_loop(shape), bridges)
