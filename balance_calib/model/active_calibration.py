"""A calibration made ready for wind-on use (TM-663 §10.1-10.2): constant-free models, the
installation's axes, the envelope and the bridges' range, checked once.

Pure (no rclpy): the live calibrator (live/calibrator_core.py), the offline reduction
(aero/pipeline.py) and the coverage of a run all start from `activate`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import datetime as _dt
from functools import cached_property
import re
from typing import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ConfigError
from ..tunnel_axes import Installation, parse_installation
from ..units import BRIDGE_OUTPUTS, COMPONENTS
from .balance_model import BalanceModel
from .calibration import Calibration
from .identity_cache import IdentityCache
from .terms import Term

MODEL_CHOICES = ('linear', 'quadratic', 'cubic', 'adopted')
DEFAULT_ENVELOPE_MARGIN = 1.1
DEFAULT_OUTPUT_RANGE_FACTOR = 2.0
# design_index: columns 0-5 the raw outputs, 6-11 their absolute values, this one a 1.0
_ONE_COLUMN = 12


def six_axis_loads(
    model: BalanceModel, outputs_mv: ArrayLike, extra: Mapping[str, np.ndarray] | None = None
) -> np.ndarray:
    """Loads (N, 6) in FX..MZ order from the six raw channels (N, 6), whatever channels the model
    uses.

    A one-channel thrust stand (inputs FXV, component FX) reads force.x and fills F_X only.
    """
    outputs = np.atleast_2d(np.asarray(outputs_mv, dtype=float))
    columns = [BRIDGE_OUTPUTS.index(name) for name in model.inputs]
    loads = np.zeros((outputs.shape[0], 6))
    loads[:, [COMPONENTS.index(c) for c in model.components]] = model.loads(
        outputs[:, columns], extra
    )
    return loads


def six_axis(values: ArrayLike, names: Sequence[str], fill: float) -> np.ndarray:
    """A per-component vector over `names` spread onto FX..MZ, `fill` where a component is
    absent.
    """
    result = np.full(6, fill, dtype=float)
    result[
        [COMPONENTS.index(n) if n in COMPONENTS else BRIDGE_OUTPUTS.index(n) for n in names]
    ] = np.asarray(values, dtype=float)
    return result


@dataclass(frozen=True)
class ActiveCalibration:
    """A calibration made ready for wind-on use: constant-free models, axes and envelope."""

    calibration: Calibration
    source: str  # file it was read from (for messages)
    requested_model: str  # the `model` parameter: 'adopted', 'cubic', ...
    model_name: str  # the key of the model in calibration.models
    model: BalanceModel  # without constant terms (§10.1)
    requires: tuple[str, ...]  # live inputs it needs: 'temperature', 'load_history'
    base_name: str  # the model that runs when an input is missing
    base_model: BalanceModel  # without constant terms
    installation: Installation
    envelope: np.ndarray  # (6,) |load| above this (N, N·m) is outside the calibrated range
    output_range_mv: np.ndarray = field(default_factory=lambda: np.full(6, np.inf))
    # (6,) |raw output| above this (mV) is a saturated bridge (inf for channels the calibration
    # lacks)

    @cached_property
    def iterative(self) -> bool:
        """The model is R-091's iterative form (outputs from loads, inverted by Newton per
        sample).
        """
        return getattr(self.model, 'form', 'direct') == 'iterative'

    @cached_property
    def plan(
        self,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        """What one sample needs, precomputed: input columns, component slots, powers,
        coefficients. An iterative model has no polynomial of the outputs: columns and slots only
        (powers None).
        """
        columns = np.array([BRIDGE_OUTPUTS.index(v) for v in self.model.inputs])
        positions = np.array([COMPONENTS.index(c) for c in self.model.components])
        if self.iterative:
            return columns, positions, None, None, None
        names, plain, absolute, has_absolute = self.model._exponents
        order = [self.model.inputs.index(v) for v in names if v in self.model.inputs]
        return (
            columns[order],
            positions,
            plain,
            absolute if has_absolute else None,
            np.array(self.model.coefficients),
        )

    @cached_property
    def design_index(self) -> np.ndarray | None:
        """A direct model's terms as products of gathered columns: (n_terms, width) indices into
        the six raw outputs, their six absolute values and a 1.0 (columns 0-5, 6-11, 12), each
        factor x^a |x|^b written a + b times and the rest padded with the 1.0; the design row of
        a sample is the product along each row (multiplications, where numpy's power calls pow()
        per element: ~20 ns each, 6 per term). None for an iterative model.
        """
        columns, _, plain, absolute, _ = self.plan
        if plain is None:
            return None
        absolute = np.zeros_like(plain) if absolute is None else absolute
        terms = []
        for powers, absolute_powers in zip(plain, absolute):  # variables in `columns` order
            factors: list[int] = []
            for column, a, b in zip(columns, powers, absolute_powers):
                factors += [int(column)] * int(a) + [6 + int(column)] * int(b)
            terms.append(factors)
        width = max([len(t) for t in terms] + [1])
        return np.array([t + [_ONE_COLUMN] * (width - len(t)) for t in terms], dtype=np.intp)

    @cached_property
    def one_sample_terms(self) -> tuple[tuple[int, ...], ...] | None:
        """Per term, the raw-output columns to multiply (with repetition): the C kernel's form
        of the model (live/sample_kernel.py), design_index without its padding; None when a term
        has an absolute value or a power beyond 3 (the kernel does not apply then), or for an
        iterative model.
        """
        _, _, plain, absolute, _ = self.plan
        index = self.design_index
        if index is None or plain is None or absolute is not None:
            return None
        if plain.size == 0 or plain.max() > 3:
            return None
        return tuple(tuple(int(i) for i in row if i != _ONE_COLUMN) for row in index)

    @cached_property
    def one_sample_index(self) -> np.ndarray | None:
        """one_sample_terms as an (n_terms, width) index into the six outputs followed by a 1.0
        (index 6): the design row of one sample is the product of each row's entries (the C
        kernel's plan).
        """
        terms = self.one_sample_terms
        if terms is None:
            return None
        width = max(len(t) for t in terms)
        return np.array([t + (6,) * (width - len(t)) for t in terms], dtype=np.intp)

    @cached_property
    def coefficients_six(self) -> np.ndarray:
        """(6, n_terms) the model's coefficients in FX..MZ rows (zero rows for components it
        lacks).
        """
        _, positions, _, _, coefficients = self.plan
        if coefficients is None:
            raise TypeError(f'model {self.model_name} is iterative: no polynomial coefficients')
        six = np.zeros((6, coefficients.shape[1]))
        six[positions] = coefficients
        return six

    @cached_property
    def coefficients_six_t(self) -> np.ndarray:
        """coefficients_six as the (n_terms, 6) matrix of design @ coefficients (a view)."""
        return self.coefficients_six.T

    @cached_property
    def output_limit_mv(self) -> np.ndarray:
        """(6,) the live calibrator's whole-batch check: |every raw output| <= this means no
        sample is saturated or non-finite (output_range_mv, the largest float where it is
        infinite, so that an infinite output fails it); a batch that fails gets per-sample masks.
        """
        limit: np.ndarray = np.minimum(self.output_range_mv, np.finfo(float).max)
        return limit

    @cached_property
    def envelope_limit(self) -> np.ndarray:
        """(6,) |every load| <= this: every load finite and inside the envelope (the check of a
        whole batch, as output_limit_mv).
        """
        limit: np.ndarray = np.minimum(self.envelope, np.finfo(float).max)
        return limit

    def layout(self, model: BalanceModel) -> tuple[np.ndarray, np.ndarray | None]:
        """The model's input columns of the six raw outputs and its components' slots in FX..MZ
        (None when it gives all six in order), cached for the active and the base model.
        """
        known = self._layouts.get(model)
        if known is not None:
            return known
        columns = np.array([BRIDGE_OUTPUTS.index(v) for v in model.inputs], dtype=np.intp)
        positions = [COMPONENTS.index(c) for c in model.components]
        slots = None if positions == list(range(6)) else np.array(positions, dtype=np.intp)
        if model is self.model or model is self.base_model:
            self._layouts.put(model, (columns, slots))
        return columns, slots

    @cached_property
    def _layouts(self) -> IdentityCache[tuple[np.ndarray, np.ndarray | None]]:
        return IdentityCache(limit=2)  # the active and the base model

    @cached_property
    def unused_inputs(self) -> np.ndarray | None:
        """Columns of the six raw outputs that the calibration does not read (a 1-, 3- or 5-bridge
        calibration), None when it reads all six: their values, NaN included, change nothing.
        """
        used = [BRIDGE_OUTPUTS.index(b) for b in self.calibration.bridge_outputs]
        unused = [i for i in range(6) if i not in used]
        return np.array(unused, dtype=np.intp) if unused else None

    def inputs_finite(self, outputs: np.ndarray) -> np.ndarray:
        """(N,) True where every raw output the calibration reads is finite; outputs (N, 6)."""
        if self.unused_inputs is None:
            finite: np.ndarray = np.isfinite(outputs).all(axis=1)
            return finite
        used = np.isfinite(outputs)
        used[:, self.unused_inputs] = True
        finite = used.all(axis=1)
        return finite

    @cached_property
    def absent_components(self) -> tuple[str, ...]:
        """Components of the published wrench (tunnel axes) that the calibration does not give
        (a 1-, 3- or 5-component balance): published as 0, their uncertainty NaN, never out of
        the envelope or overloaded.
        """
        present = set(self.calibration.components)
        return tuple(
            COMPONENTS[i]
            for i, p in enumerate(self.installation.permutation)
            if COMPONENTS[p] not in present
        )

    @property
    def capacity(self) -> np.ndarray:
        """(6,) full scale per component FX..MZ (inf for components the calibration lacks)."""
        return six_axis(self.calibration.capacity, self.calibration.components, np.inf)

    def age_days(self, now: _dt.datetime | None = None) -> float | None:
        fitted = self.calibration.fitted_datetime
        if fitted is None:
            return None
        now = now or _dt.datetime.now(_dt.timezone.utc)
        if fitted.tzinfo is None:
            fitted = fitted.replace(tzinfo=_dt.timezone.utc)
        return (now - fitted).total_seconds() / 86400.0


def live_variable_names(model: BalanceModel, renames: Mapping[str, str]) -> BalanceModel:
    """The model with its variables renamed (a table's dTEMP -> dT): the live calibrator feeds
    dT from /balance/temperature less the calibration's reference_temperature_c.
    """
    used = set(renames) & set(model.extra_variables)
    if not used:
        return model
    pattern = re.compile(r'\b(' + '|'.join(map(re.escape, sorted(used))) + r')\b')
    terms = tuple(
        Term.parse(pattern.sub(lambda m: renames[m.group(1)], t.name)) for t in model.terms
    )
    return replace(model, terms=terms)


def activate(
    calibration: Calibration,
    model: str = 'adopted',
    installation: str | Installation = 'upright',
    envelope_margin: float = DEFAULT_ENVELOPE_MARGIN,
    source: str = '',
    output_range_factor: float = DEFAULT_OUTPUT_RANGE_FACTOR,
) -> ActiveCalibration:
    """Check that `model` and `installation` make sense for `calibration` and prepare it.

    Raises ConfigError (model missing from the calibration, capacities or rated outputs not
    positive finite numbers) or ValueError (installation, margin, range factor).
    """
    if not isinstance(installation, Installation):
        installation = parse_installation(installation)
    if not np.isfinite(envelope_margin) or not 0.5 <= envelope_margin <= 10.0:
        raise ValueError(
            f'envelope_margin must be between 0.5 and 10 (x capacity), not {envelope_margin}'
        )
    if not np.isfinite(output_range_factor) or not 1.0 <= output_range_factor <= 100.0:
        raise ValueError(
            'output_range_factor must be between 1 and 100 (x rated output), not '
            f'{output_range_factor}'
        )
    _check_channels(calibration, source)
    for what, values, names in (
        ('capacity', calibration.capacity, calibration.components),
        ('rated_output_mv', calibration.rated_output_mv, calibration.bridge_outputs),
    ):
        bad = [
            f'{n}={v}'
            for n, v in zip(names, np.asarray(values, dtype=float))
            if not (np.isfinite(v) and v > 0)
        ]
        if bad:
            raise ConfigError(
                f'{source or calibration.balance}: {what} must be positive finite numbers '
                f'({", ".join(bad)})'
            )
    chosen = calibration.model(model)  # ConfigError names the models it has
    model_name = calibration.adopted if model in ('adopted', '') else model
    requires = calibration.requires(model_name)
    unprovided = [r for r in requires if r not in ('temperature', 'load_history')]
    if unprovided:
        raise ConfigError(
            f'{source or calibration.balance}: model {model_name!r} reads channel '
            f'{", ".join(unprovided)}, which no topic provides (only temperature comes in, on '
            f'/balance/temperature); choose another model of the calibration (it has '
            f'{", ".join(calibration.models)}) or fit it without that channel'
        )
    chosen = live_variable_names(chosen, calibration.temperature_variables())
    base_name = (
        calibration.base_model if calibration.base_model in calibration.models else model_name
    )
    base = calibration.models[base_name]
    if base.extra_variables:  # a base that needs inputs itself is no fallback
        base_name, base = model_name, chosen
    return ActiveCalibration(
        calibration,
        source,
        model,
        model_name,
        chosen.without_constant(),
        requires,
        base_name,
        base.without_constant(),
        installation,
        float(envelope_margin) * six_axis(calibration.capacity, calibration.components, np.inf),
        float(output_range_factor)
        * np.abs(six_axis(calibration.rated_output_mv, calibration.bridge_outputs, np.inf)),
    )


def _check_channels(calibration: Calibration, source: str) -> None:
    """The live calibrator reads six raw channels (FXV..MZV in force.x..torque.z of balance/raw)
    and publishes six components (FX..MZ): a calibration under other names (a table's own
    symbols) or with more bridge outputs than that (an 8-channel sensor) is refused in one line.
    """
    where = source or calibration.balance
    for what, names, known, verb in (
        ('components', calibration.components, COMPONENTS, 'publishes'),
        ('bridge outputs', calibration.bridge_outputs, BRIDGE_OUTPUTS, 'reads'),
    ):
        if set(names) <= set(known) and len(set(names)) == len(names):
            continue
        raise ConfigError(
            f'{where}: {what} {", ".join(names)}: balance_calibrator {verb} only '
            f'{", ".join(known)}, each once, so this calibration ({len(calibration.components)} '
            f'components from {len(calibration.bridge_outputs)} bridge outputs) cannot run live '
            f"(balance-calib fit --axes names a table's loads and bridges as TM-663's)"
        )
