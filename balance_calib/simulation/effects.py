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

from ..model.balance_model import BalanceModel
from ..model.terms import parse_terms


@dataclass(frozen=True)
class SampleContext:
    """Per-sample facts an effect may depend on (S samples)."""

    times_s: np.ndarray            # (S,)
    temperature_c: np.ndarray      # (S,)
    loads: np.ndarray              # (S, 6) true total load (applied + body), N / N·m
    outputs_mv: np.ndarray         # (S, 6) outputs of the balance without effects (no zero, no noise)
    direction: np.ndarray          # (S, 6) +1 if the load on that bridge last rose, -1 if it fell
    rated_output_mv: np.ndarray    # (6,)
    reference_temperature_c: float


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

    zero_mv_per_k: Sequence[float] | float = 0.0
    sensitivity_per_k: Sequence[float] | float = 0.0
    name = 'temperature'

    def outputs(self, outputs_mv, ctx):
        d_t = (ctx.temperature_c - ctx.reference_temperature_c)[:, None]
        return outputs_mv + _vector(self.zero_mv_per_k) * d_t + _vector(self.sensitivity_per_k) * d_t * ctx.outputs_mv


@dataclass(frozen=True)
class ZeroDrift(Effect):
    """Zero wandering faster than the bracketing zero points follow: a sum of sines, mV per bridge."""

    amplitude_mv: Sequence[float] | float = 0.0
    period_s: float = 900.0
    phase: float = 0.3
    name = 'zero_drift'

    def outputs(self, outputs_mv, ctx):
        t = ctx.times_s[:, None]
        wave = np.sin(2 * np.pi * t / self.period_s + self.phase) + 0.5 * np.sin(2 * np.pi * t / (0.37 * self.period_s))
        return outputs_mv + _vector(self.amplitude_mv) * wave / 1.5


@dataclass(frozen=True)
class Hysteresis(Effect):
    """Output depends on whether the load on that bridge was rising or falling: ±h of rated output."""

    fraction_of_rated: Sequence[float] | float = 0.0
    name = 'hysteresis'

    def outputs(self, outputs_mv, ctx):
        return outputs_mv + _vector(self.fraction_of_rated) * ctx.rated_output_mv * ctx.direction


@dataclass(frozen=True)
class Bidirectional(Effect):
    """Different sensitivity for positive and negative load: V += b·|V| (b per bridge)."""

    asymmetry: Sequence[float] | float = 0.0
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
        extra = [t.name for t in parse_terms({n for row in self.coefficients.values() for n in row})
                 if t.name not in names]
        terms = tuple(model.terms) + parse_terms(sorted(extra))
        coefficients = np.hstack([np.array(model.coefficients), np.zeros((len(model.components), len(extra)))])
        all_names = [t.name for t in terms]
        for component, row in self.coefficients.items():
            for term, value in row.items():
                index = all_names.index(parse_terms([term])[0].name)
                coefficients[model.components.index(component), index] += value
        return BalanceModel(model.name + '+cross', terms, coefficients, model.components, model.inputs)


@dataclass(frozen=True)
class HeavierBody(Effect):
    """The calibration body weighs more (or less) than declared: factor on its weight."""

    weight_factor: float = 1.0
    name = 'tare'

    def body_weight_factor(self):
        return self.weight_factor


EFFECTS = {cls.name: cls for cls in (Temperature, ZeroDrift, Hysteresis, Bidirectional, CrossTerms, HeavierBody)}


def parse_effects(spec: str) -> list[Effect]:
    """Effects from a parameter string, e.g.
    "temperature:sensitivity_per_k=2e-4; hysteresis:fraction_of_rated=3e-4; tare:weight_factor=1.01;
     cross_terms:FX.FXV^2*FZV=40; bidirectional:asymmetry=1e-3|0|0|0|0|0; zero_drift:amplitude_mv=0.002,period_s=900"
    Values are numbers, or per-bridge lists separated by |. Raises ValueError naming the bad part.
    """
    names = {'tare': HeavierBody, **EFFECTS}
    effects: list[Effect] = []
    for part in (p.strip() for p in (spec or '').split(';')):
        if not part:
            continue
        name, _, args = part.partition(':')
        name = name.strip()
        if name not in names:
            raise ValueError(f'unknown effect {name!r} in {spec!r}; known: {", ".join(sorted(names))}')
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
            effects.append(names[name](coefficients=cross) if name == 'cross_terms' else names[name](**kwargs))
        except TypeError as err:
            raise ValueError(f'effect {name}: {err}') from None
    return effects
