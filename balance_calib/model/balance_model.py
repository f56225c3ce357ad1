"""A balance model: loads = coefficients · terms(bridge outputs [, other variables]).

TM-663 eqs. (1)-(18) are the instances with the term lists of `tm663.py`; any other term list
(absolute-value, temperature, hysteresis terms, one channel) is the same object.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..array_types import FloatArray
from ..units import BRIDGE_OUTPUTS, COMPONENTS
from .terms import as_variables, parse_terms, power_products, Term, term_exponents
from .tm663 import coefficient_number, tm663_terms


@dataclass(frozen=True)
class BalanceModel:
    """Coefficients (n_components, n_terms) over a term list; loads in N / N·m from outputs in mV.

    `inputs` are the bridge-output columns of the array passed to `loads`; terms may also use
    other variables (e.g. "dT"), passed by name in `extra`.
    """

    name: str
    terms: tuple[Term, ...]
    coefficients: np.ndarray
    components: tuple[str, ...] = COMPONENTS
    inputs: tuple[str, ...] = BRIDGE_OUTPUTS
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        coefficients = np.asarray(self.coefficients, dtype=float)
        expected = (len(self.components), len(self.terms))
        if coefficients.shape != expected:
            raise ValueError(
                f'model {self.name}: coefficients have shape {coefficients.shape}, '
                f'expected {expected} (components x terms)'
            )
        if not np.all(np.isfinite(coefficients)):
            raise ValueError(f'model {self.name}: coefficients contain NaN or infinity')
        coefficients.setflags(write=False)
        object.__setattr__(self, 'coefficients', coefficients)

    # --- construction -------------------------------------------------------------------------
    @classmethod
    def tm663(cls, order: str, coefficients: ArrayLike, **kwargs: Any) -> 'BalanceModel':
        return cls(order, tm663_terms(order), np.asarray(coefficients, dtype=float), **kwargs)

    @classmethod
    def zeros(
        cls,
        name: str,
        terms: Sequence[Term],
        components: Sequence[str] = COMPONENTS,
        inputs: Sequence[str] = BRIDGE_OUTPUTS,
    ) -> 'BalanceModel':
        return cls(
            name,
            tuple(terms),
            np.zeros((len(components), len(terms))),
            tuple(components),
            tuple(inputs),
        )

    # --- properties ---------------------------------------------------------------------------
    @cached_property
    def term_names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.terms)

    @cached_property
    def variables(self) -> tuple[str, ...]:
        """Every variable the terms need (inputs first)."""
        needed = {v for t in self.terms for v in t.variables}
        return tuple(v for v in self.inputs if v in needed) + tuple(
            sorted(needed - set(self.inputs))
        )

    @cached_property
    def extra_variables(self) -> tuple[str, ...]:
        return tuple(v for v in self.variables if v not in self.inputs)

    def term_index(self, name: str) -> int:
        return self.term_names.index(Term.parse(name).name)

    def coefficient(self, component: str, term: str) -> float:
        return float(self.coefficients[self.components.index(component), self.term_index(term)])

    def coefficient_number(self, component: str, term: str) -> int:
        """The memo's C index of a coefficient (eqs. (1)-(18) numbering)."""
        return coefficient_number(
            self.components.index(component), self.term_index(term), len(self.terms)
        )

    # --- evaluation ---------------------------------------------------------------------------
    @cached_property
    def _exponents(self) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, bool]:
        """Variables, and the powers of each (plain, absolute) in each term: (n_terms, n_vars)
        whole numbers as floats (numpy casts integer exponents to float on every call).
        """
        plain, absolute = term_exponents(self.terms, self.variables)
        return self.variables, plain.astype(float), absolute.astype(float), bool(absolute.any())

    def design(
        self, bridge_outputs_mv: ArrayLike, extra: Mapping[str, np.ndarray] | None = None
    ) -> np.ndarray:
        """(N, n_terms): every term on every sample, as products of powers (one numpy
        expression).
        """
        outputs = np.atleast_2d(np.asarray(bridge_outputs_mv, dtype=float))
        if outputs.shape[1] != len(self.inputs):
            raise ValueError(
                f'expected {len(self.inputs)} columns ({", ".join(self.inputs)}), got '
                f'{outputs.shape[1]}'
            )
        names, plain, absolute, has_absolute = self._exponents
        extra_names = names[len([v for v in names if v in self.inputs]) :]
        missing = [v for v in extra_names if not extra or v not in extra]
        if missing:
            raise KeyError(
                f'the model needs variable(s) {", ".join(missing)} that the data does not have'
            )
        columns = [
            outputs[:, self.inputs.index(v)] for v in names[: len(names) - len(extra_names)]
        ]
        given = extra or {}  # every extra name is in `extra` (checked above)
        columns += [
            np.broadcast_to(np.asarray(given[v], dtype=float), (outputs.shape[0],))
            for v in extra_names
        ]
        values = np.column_stack(columns) if columns else np.zeros((outputs.shape[0], 0))
        return power_products(values, plain, absolute if has_absolute else None)

    def loads(
        self, bridge_outputs_mv: ArrayLike, extra: Mapping[str, np.ndarray] | None = None
    ) -> np.ndarray:
        """Loads (N, n_components) from outputs (N, n_inputs), TM-663 eqs. (1)-(18)."""
        single = np.ndim(bridge_outputs_mv) == 1
        result: FloatArray = self.design(bridge_outputs_mv, extra) @ self.coefficients.T
        return result[0] if single else result

    def jacobian(
        self, bridge_outputs_mv: ArrayLike, extra: Mapping[str, np.ndarray] | None = None
    ) -> np.ndarray:
        """D loads / d outputs, shape (N, n_components, n_inputs)."""
        outputs = np.atleast_2d(np.asarray(bridge_outputs_mv, dtype=float))
        n = outputs.shape[0]
        variables = as_variables(self.inputs, outputs, extra)
        jac = np.empty((n, len(self.components), len(self.inputs)))
        for i, name in enumerate(self.inputs):
            # a term without the input has a zero derivative: only the others are evaluated
            d_design = np.zeros((n, len(self.terms)))
            for j, term in enumerate(self.terms):
                if name in term.variables:
                    d_design[:, j] = term.derivative(name, variables, n)
            jac[:, :, i] = d_design @ self.coefficients.T
        return jac

    # --- variants -----------------------------------------------------------------------------
    def without_constant(self) -> 'BalanceModel':
        """Wind-on form, TM-663 §10.1: C1 = C8 = ... = 0 (the constant of every component)."""
        coefficients = np.array(self.coefficients)
        for j, term in enumerate(self.terms):
            if term.is_constant:
                coefficients[:, j] = 0.0
        return replace(self, coefficients=coefficients)

    def restricted_to(self, term_names: Sequence[str], name: str | None = None) -> 'BalanceModel':
        """The same coefficients on a sub-list of terms (e.g. the base model of an augmented
        one).
        """
        indices = [self.term_index(t) for t in term_names]
        return replace(
            self,
            name=name or self.name,
            terms=tuple(self.terms[i] for i in indices),
            coefficients=self.coefficients[:, indices],
        )

    def with_coefficients(
        self, coefficients: ArrayLike, name: str | None = None, **metadata: Any
    ) -> 'BalanceModel':
        return replace(
            self,
            coefficients=np.asarray(coefficients, dtype=float),
            name=name or self.name,
            metadata={**self.metadata, **metadata},
        )

    # --- files --------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Plain data for YAML: terms in order, one coefficient row per component."""
        return {
            'name': self.name,
            'components': list(self.components),
            'inputs': list(self.inputs),
            'terms': list(self.term_names),
            'coefficients': {
                c: [float(x) for x in row] for c, row in zip(self.components, self.coefficients)
            },
            **({'metadata': dict(self.metadata)} if self.metadata else {}),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = 'model') -> 'BalanceModel':
        """Inverse of `to_dict`; errors name `where` (file and key) and what is wrong."""
        try:
            terms = parse_terms(data['terms'])
            components = tuple(data.get('components', COMPONENTS))
            inputs = tuple(data.get('inputs', BRIDGE_OUTPUTS))
            rows = data['coefficients']
            missing = [c for c in components if c not in rows]
            if missing:
                raise ValueError(f'no coefficients for {", ".join(missing)}')
            coefficients = np.array([[float(x) for x in rows[c]] for c in components])
        except KeyError as err:
            raise ValueError(f'{where}: missing key {err.args[0]!r}') from None
        except (TypeError, ValueError) as err:
            raise ValueError(f'{where}: {err}') from None
        if coefficients.shape[1] != len(terms):
            raise ValueError(
                f'{where}: {coefficients.shape[1]} coefficients per component '
                f'but {len(terms)} terms'
            )
        return cls(
            str(data.get('name', 'custom')),
            terms,
            coefficients,
            components,
            inputs,
            dict(data.get('metadata', {}) or {}),
        )
