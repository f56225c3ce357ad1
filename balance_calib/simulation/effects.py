"""Effects a real balance has and the base model of TM-663 lacks, for simulated campaigns.

Each effect acts on the simulated outputs sample by sample, given a context with the time,
temperature, true loads and load history. None of them is known to the refit: they are what the
diagnosis of the residuals (diagnosis/) has to find. Sizes are given in physical units; see
`SIZES_NOTE` for what 'a few times the noise floor' means for them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..model.balance_model import BalanceModel
from ..model.terms import parse_terms


@dataclass(frozen=True)
class SampleContext:
    """Per-sample facts an effect may depend on (S samples)."""

    times_s: np.ndarray  # (S,)
    temperature_c: np.ndarray  # (S,)
    loads: np.ndarray  # (S, 6) true total load (applied + body), N / N·m
    outputs_mv: np.ndarray  # (S, 6) outputs of the balance without effects (no zero, no noise)
    direction: np.ndarray  # (S, 6) +1 if the load on that bridge last rose, -1 if it fell
    rated_output_mv: np.ndarray  # (6,)
    reference_temperature_c: float
    capacity: np.ndarray | None = None  # (6,) rated loads, N / N·m
    gravity: np.ndarray | None = None  # (S, 3) unit gravity vector, balance axes
    settled_since_s: np.ndarray | None = None  # (S,) physical time the sample's load was reached


class Effect:
    name = 'effect'

    def truth(self, model: BalanceModel) -> BalanceModel:
        """Effects that change the load -> output relation itself return a new truth model."""
        return model

    def outputs(self, outputs_mv: np.ndarray, ctx: SampleContext) -> np.ndarray:
        return outputs_mv

    def body_weight_factor(self) -> float:
        return 1.0


def _vector(values, n=6) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    return np.broadcast_to(array, (n,)).copy() if array.ndim == 0 else array


@dataclass(frozen=True)
class Temperature(Effect):
    """Zero and sensitivity moving with balance temperature: V += z·dT, V *= (1 + s·dT).

    zero_mv_per_k and sensitivity_per_k per bridge (scalars broadcast). The zero part is largely
    removed by the zero points of §5(4); the sensitivity part is what they cannot remove.
    """

    zero_mv_per_k: ArrayLike = 0.0
    sensitivity_per_k: ArrayLike = 0.0
    name = 'temperature'

    def outputs(self, outputs_mv, ctx):
        d_t = (ctx.temperature_c - ctx.reference_temperature_c)[:, None]
        return (
            outputs_mv
            + _vector(self.zero_mv_per_k) * d_t
            + _vector(self.sensitivity_per_k) * d_t * ctx.outputs_mv
        )


@dataclass(frozen=True)
class ZeroDrift(Effect):
    """Zero wandering faster than the bracketing zero points follow: a sum of sines, mV per
    bridge.
    """

    amplitude_mv: ArrayLike = 0.0
    period_s: float = 900.0
    phase: float = 0.3
    name = 'zero_drift'

    def outputs(self, outputs_mv, ctx):
        t = ctx.times_s[:, None]
        wave = np.sin(2 * np.pi * t / self.period_s + self.phase) + 0.5 * np.sin(
            2 * np.pi * t / (0.37 * self.period_s)
        )
        return outputs_mv + _vector(self.amplitude_mv) * wave / 1.5


@dataclass(frozen=True)
class Hysteresis(Effect):
    """Output depends on whether the load on that bridge was rising or falling: ±h of rated
    output.
    """

    fraction_of_rated: ArrayLike = 0.0
    name = 'hysteresis'

    def outputs(self, outputs_mv, ctx):
        return outputs_mv + _vector(self.fraction_of_rated) * ctx.rated_output_mv * ctx.direction


@dataclass(frozen=True)
class Bidirectional(Effect):
    """Different sensitivity for positive and negative load: V += b·|V| (b per bridge)."""

    asymmetry: ArrayLike = 0.0
    name = 'bidirectional'

    def outputs(self, outputs_mv, ctx):
        return outputs_mv + _vector(self.asymmetry) * np.abs(ctx.outputs_mv)


@dataclass(frozen=True)
class CrossTerms(Effect):
    """Interactions the cubic form of §2.3 lacks, added to the truth (N or N·m per term unit).

    coefficients: {component: {term name: coefficient}}, e.g. {'FX': {'FXV^2*FZV': 3.0}}.
    """

    coefficients: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    name = 'cross_terms'

    def truth(self, model):
        names = list(model.term_names)
        extra = [
            t.name
            for t in parse_terms({n for row in self.coefficients.values() for n in row})
            if t.name not in names
        ]
        terms = tuple(model.terms) + parse_terms(sorted(extra))
        coefficients = np.hstack(
            [np.array(model.coefficients), np.zeros((len(model.components), len(extra)))]
        )
        all_names = [t.name for t in terms]
        for component, row in self.coefficients.items():
            for term, value in row.items():
                index = all_names.index(parse_terms([term])[0].name)
                coefficients[model.components.index(component), index] += value
        return BalanceModel(
            model.name + '+cross', terms, coefficients, model.components, model.inputs
        )


@dataclass(frozen=True)
class HeavierBody(Effect):
    """The calibration body weighs more (or less) than declared: factor on its weight."""

    weight_factor: float = 1.0
    name = 'tare'

    def body_weight_factor(self):
        return self.weight_factor


# --- alternative shapes ------------------------------------------------------------------------
# Written from the physics, not from the diagnosis's candidate terms (diagnosis/candidates.py): the
# diagnosis has to find these with terms that fit them only approximately.


def _play(values: np.ndarray, half_width: np.ndarray) -> np.ndarray:
    """Play (backlash) operator on each column of values (S, n), starting at the first value."""
    out = np.empty_like(values)
    state = values[0].copy()
    for i, v in enumerate(values):
        state = np.minimum(np.maximum(state, v - half_width), v + half_width)
        out[i] = state
    return out


@dataclass(frozen=True)
class PlayHysteresis(Effect):
    """A hysteresis loop of play-operator (Preisach, one hysteron) shape on each bridge.

    The offset follows the output through a backlash of half-width width_fraction x rated output:
    it moves linearly away from a turning point and saturates at ±fraction_of_rated x rated output
    once the load has moved 2 x width past it. Small load reversals give small loops.
    """

    fraction_of_rated: ArrayLike = 0.0
    width_fraction: float = 0.25
    name = 'hysteresis'

    def outputs(self, outputs_mv, ctx):
        half = self.width_fraction * ctx.rated_output_mv
        lag = (ctx.outputs_mv - _play(ctx.outputs_mv, half)) / half  # in [-1, 1]
        return outputs_mv + _vector(self.fraction_of_rated) * ctx.rated_output_mv * lag


@dataclass(frozen=True)
class TurningPointHysteresis(Effect):
    """Loop offset growing with the distance the load travelled since its last turning point:
    ±h x rated x (1 - exp(-|V - V_turn| / (scale x rated))), sign of the direction of travel.
    """

    fraction_of_rated: ArrayLike = 0.0
    scale_fraction: float = 0.3
    name = 'hysteresis'

    def outputs(self, outputs_mv, ctx):
        v, d = ctx.outputs_mv, ctx.direction
        turn = np.empty_like(v)
        turn[0] = v[0]
        for i in range(1, len(v)):
            changed = d[i] != d[i - 1]
            turn[i] = np.where(changed, v[i - 1], turn[i - 1])
        grow = 1.0 - np.exp(-np.abs(v - turn) / (self.scale_fraction * ctx.rated_output_mv))
        return outputs_mv + _vector(self.fraction_of_rated) * ctx.rated_output_mv * d * grow


def lagged_temperature(times_s, temperature_c, lag_s: float) -> np.ndarray:
    """First-order lag of the temperature (the gauges follow the case with time constant lag_s)."""
    if lag_s <= 0:
        return np.asarray(temperature_c, float)
    out = np.empty(len(times_s))
    out[0] = temperature_c[0]
    for i in range(1, len(times_s)):
        w = np.exp(-max(times_s[i] - times_s[i - 1], 0.0) / lag_s)
        out[i] = w * out[i - 1] + (1 - w) * temperature_c[i]
    return out


@dataclass(frozen=True)
class TemperatureShapes(Effect):
    """Temperature acting through dT² and/or a lagged gauge temperature:
    V += z2·dT'² and V *= 1 + s·dT' + s2·dT'², dT' the gauge temperature lagging the measured one
    by a first-order lag of lag_s (0: no lag). The refit only sees the measured temperature.
    """

    sensitivity_per_k: ArrayLike = 0.0
    sensitivity_per_k2: ArrayLike = 0.0
    zero_mv_per_k2: ArrayLike = 0.0
    lag_s: float = 0.0
    name = 'temperature'

    def outputs(self, outputs_mv, ctx):
        gauge = lagged_temperature(ctx.times_s, ctx.temperature_c, self.lag_s)
        d_t = (gauge - ctx.reference_temperature_c)[:, None]
        gain = _vector(self.sensitivity_per_k) * d_t + _vector(self.sensitivity_per_k2) * d_t**2
        return outputs_mv + _vector(self.zero_mv_per_k2) * d_t**2 + gain * ctx.outputs_mv


def _load_steps(ctx: SampleContext):
    """(step times (M,), output changes (M, 6)) of the load history, in time order."""
    v = ctx.outputs_mv
    changed = np.any(np.abs(np.diff(v, axis=0)) > 1e-12, axis=1)
    index = np.where(changed)[0] + 1
    since = ctx.settled_since_s if ctx.settled_since_s is not None else ctx.times_s
    times = np.concatenate([[since[0]], since[index]])
    steps = np.vstack([v[:1], v[index] - v[index - 1]])
    return times, steps


@dataclass(frozen=True)
class Creep(Effect):
    """Output relaxing after each load change with two time constants:
    V(t) = V - c Σ_i ΔV_i Σ_j w_j exp(-(t - t_i)/τ_j) over the load steps i before t.
    """

    fraction: ArrayLike = 0.0
    time_constants_s: Sequence[float] = (40.0, 400.0)
    weights: Sequence[float] = (0.6, 0.4)
    name = 'creep'

    def outputs(self, outputs_mv, ctx):
        step_times, steps = _load_steps(ctx)
        age = ctx.times_s[:, None] - step_times[None, :]  # (S, M)
        kernel = np.zeros_like(age)
        for tau, w in zip(self.time_constants_s, self.weights):
            kernel += w * np.exp(-np.clip(age, 0.0, None) / tau)
        kernel[age < 0] = 0.0
        return outputs_mv - _vector(self.fraction) * (kernel @ steps)


@dataclass(frozen=True)
class SupplyDrift(Effect):
    """The bridge supply (excitation) drifting: every bridge output x (1 + g(t)),
    g = gain_per_hour x hours + the steps (time s, relative step) that have happened by then.
    """

    gain_per_hour: float = 0.0
    steps: Sequence[Sequence[float]] = ()
    name = 'excitation'

    def outputs(self, outputs_mv, ctx):
        t = ctx.times_s - ctx.times_s[0]
        gain = self.gain_per_hour * t / 3600.0
        for when, size in self.steps:
            gain = gain + size * (t >= when)
        return outputs_mv + gain[:, None] * ctx.outputs_mv


@dataclass(frozen=True)
class LoadSignBidirectional(Effect):
    """Sensitivity different for positive and negative *load* on a component (not output):
    V_k += b_k x rated output_k x |L_k| / capacity_k.
    """

    asymmetry: ArrayLike = 0.0
    name = 'bidirectional'

    def outputs(self, outputs_mv, ctx):
        return (
            outputs_mv
            + _vector(self.asymmetry) * ctx.rated_output_mv * np.abs(ctx.loads) / ctx.capacity
        )


# --- outside every family: what the diagnosis must call "unexplained" ------------------------
@dataclass(frozen=True)
class NeighbourDeadBand(Effect):
    """A load on one component leaking into the next bridge only beyond a dead band:
    V_target += a x rated_target x max(|L_source|/capacity - d, 0) / (1 - d).
    """

    fraction_of_rated: float = 0.0
    source: int = 0
    target: int = 1
    dead_band: float = 0.4
    name = 'neighbour_dead_band'

    def outputs(self, outputs_mv, ctx):
        source, target = int(self.source), int(self.target)  # a parameter string gives floats
        x = np.abs(ctx.loads[:, source]) / ctx.capacity[source]
        leak = np.clip(x - self.dead_band, 0.0, None) / (1.0 - self.dead_band)
        out = outputs_mv.copy()
        out[:, target] += self.fraction_of_rated * ctx.rated_output_mv[target] * leak
        return out


@dataclass(frozen=True)
class GravityTimeNonlinearity(Effect):
    """A bridge curvature that grows in time and flips with the gravity direction:
    V_k += a x g_z x (t / campaign) x V_k |V_k| / rated_k (a mounting that settles under its own
    weight).
    """

    fraction_of_rated: ArrayLike = 0.0
    name = 'gravity_time'

    def outputs(self, outputs_mv, ctx):
        t = ctx.times_s - ctx.times_s[0]
        span = max(float(t[-1]), 1e-9)
        g = ctx.gravity[:, 2:3] + 0.5 * ctx.gravity[:, 1:2]
        shape = ctx.outputs_mv * np.abs(ctx.outputs_mv) / ctx.rated_output_mv
        return outputs_mv + _vector(self.fraction_of_rated) * g * (t / span)[:, None] * shape


EFFECTS = {
    cls.name: cls
    for cls in (Temperature, ZeroDrift, Hysteresis, Bidirectional, CrossTerms, HeavierBody)
}
ALTERNATIVE_EFFECTS = {
    'play_hysteresis': PlayHysteresis,
    'turning_hysteresis': TurningPointHysteresis,
    'temperature_shapes': TemperatureShapes,
    'creep': Creep,
    'supply_drift': SupplyDrift,
    'load_sign_bidirectional': LoadSignBidirectional,
    'neighbour_dead_band': NeighbourDeadBand,
    'gravity_time': GravityTimeNonlinearity,
}


def parse_effects(spec: str) -> list[Effect]:
    """Effects from a parameter string, e.g.
    "temperature:sensitivity_per_k=2e-4; hysteresis:fraction_of_rated=3e-4;
    tare:weight_factor=1.01;
     cross_terms:FX.FXV^2*FZV=40; bidirectional:asymmetry=1e-3|0|0|0|0|0;
     zero_drift:amplitude_mv=0.002,period_s=900"
    Values are numbers, or per-bridge lists separated by |. Raises ValueError naming the bad part.
    """
    names = {'tare': HeavierBody, **EFFECTS, **ALTERNATIVE_EFFECTS}
    effects: list[Effect] = []
    for part in (p.strip() for p in (spec or '').split(';')):
        if not part:
            continue
        name, _, args = part.partition(':')
        name = name.strip()
        if name not in names:
            raise ValueError(
                f'unknown effect {name!r} in {spec!r}; known: {", ".join(sorted(names))}'
            )
        kwargs: dict = {}
        cross: dict = {}
        for item in (a.strip() for a in args.split(',') if a.strip()):
            key, eq, value = item.partition('=')
            if not eq:
                raise ValueError(f'effect {name}: expected key=value, got {item!r}')
            try:
                number = [float(v) for v in value.split('|')] if '|' in value else float(value)
            except ValueError:
                raise ValueError(f'effect {name}: {key} = {value!r} is not a number') from None
            if name == 'cross_terms':
                component, _, term = key.strip().partition('.')
                cross.setdefault(component, {})[term] = float(number)
            else:
                kwargs[key.strip()] = number
        try:
            effects.append(
                names[name](coefficients=cross) if name == 'cross_terms' else names[name](**kwargs)
            )
        except TypeError as err:
            raise ValueError(f'effect {name}: {err}') from None
    return effects
