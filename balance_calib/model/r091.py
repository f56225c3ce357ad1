"""AIAA R-091's iterative method: bridge outputs as a polynomial of the loads, inverted per point.

The 96-term set for six loads (R-091's recommended "full" math model, the one BALFIT starts from):

    per load (6 loads x 6 forms = 36):  F, |F|, F², F·|F|, F³, |F³|
    per pair (15 pairs x 4 forms = 60): Fi·Fj, |Fi·Fj|, Fi·|Fj|, |Fi|·Fj
    total 36 + 60 = 96 (no constant: outputs are measured from the natural zero)

`IterativeModel` holds outputs = coefficients · g(loads) (n_outputs x n_terms) and evaluates loads
from outputs by vectorised Newton iteration, through the same `loads(outputs, extra)` interface as
`BalanceModel`, so a calibration.yaml holding one runs in the same places.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from itertools import combinations
from pathlib import Path
from typing import Any, cast, Literal, Mapping, NoReturn, overload, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..plain_data import plain_data as _plain
from .inverse import InverseDidNotConverge
from .terms import parse_terms, Term, term_exponents
from .tm663 import tm663_terms

TERM_SETS = ('tm663-cubic', 'r091-96')


def r091_terms(variables: Sequence[str]) -> tuple[Term, ...]:
    """R-091's 96-term set (for six variables; 6n + 4·n(n-1)/2 terms for n)."""
    names = []
    for v in variables:
        names += [v, f'|{v}|', f'{v}^2', f'{v}*|{v}|']
    for a, b in combinations(variables, 2):
        names += [f'{a}*{b}', f'|{a}|*|{b}|', f'{a}*|{b}|', f'|{a}|*{b}']
    for v in variables:
        names += [f'{v}^3', f'|{v}|^3']
    return parse_terms(names)


def tm663_cubic_terms(variables: Sequence[str]) -> tuple[Term, ...]:
    """TM-663's cubic form (eqs. (13)-(18)) without its constant: series tares take that role."""
    return tuple(t for t in tm663_terms('cubic', tuple(variables)) if not t.is_constant)


def rename_terms(terms: Sequence[Term], mapping: Mapping[str, str]) -> tuple[Term, ...]:
    """The same terms with their variables renamed (load symbols <-> output symbols by column)."""
    from .terms import Factor

    return tuple(
        Term(
            tuple(
                Factor(mapping.get(f.variable, f.variable), f.power, f.absolute) for f in t.factors
            )
        )
        for t in terms
    )


def term_set(
    spec: str, variables: Sequence[str], other_variables: Sequence[str] = ()
) -> tuple[Term, ...]:
    """Terms by name ('tm663-cubic', 'r091-96') or from a file (one term per line or comma
    separated, '#' comments), in `variables`. A file may name either the load or the output
    symbols; names of `other_variables` are mapped by column position onto `variables`. Raises
    ValueError naming the problem.
    """
    if spec == 'tm663-cubic':
        return tm663_cubic_terms(variables)
    if spec == 'r091-96':
        return r091_terms(variables)
    path = Path(spec)
    if not path.is_file():
        raise ValueError(f'--terms {spec!r}: neither {", ".join(TERM_SETS)} nor a readable file')
    names = []
    for line_number, line in enumerate(path.read_text().splitlines(), 1):
        text = line.split('#', 1)[0]
        names += [n.strip() for n in text.split(',') if n.strip()]
    try:
        terms = parse_terms(names)
    except ValueError as err:
        raise ValueError(f'{path}: {err}') from None
    terms = rename_terms(terms, dict(zip(other_variables, variables)))
    unknown = sorted({v for t in terms for v in t.variables} - set(variables))
    if unknown:
        raise ValueError(
            f'{path}: term variable(s) {", ".join(unknown)} are not among {", ".join(variables)}'
        )
    constant = [t.name for t in terms if t.is_constant]
    if constant:
        # the series tares take the constant's role
        terms = tuple(t for t in terms if not t.is_constant)
    if not terms:
        raise ValueError(f'{path}: no terms')
    return terms


class TermEvaluator:
    """Design matrix g(X) (N, p) and its derivatives dg/dX_v, without numpy powers or per-term
    loops.

    A term is a product of at most K single-variable factors x_v^a·|x_v|^b. The distinct factors of
    all terms form one table F (N, 1 + n_factors) built from the powers of each variable (by
    multiplication); every term is then K column gathers of F and a product, and its derivative
    replaces one gathered factor by the factor's derivative.
    """

    def __init__(self, terms: Sequence[Term], variables: Sequence[str]):
        plain, absolute = term_exponents(tuple(terms), tuple(variables))
        self.variables = tuple(variables)
        self.n_terms = len(terms)
        factor_index: dict[tuple[int, int, int], int] = {}
        per_term = []
        for j in range(len(terms)):
            keys = [
                (v, int(plain[j, v]), int(absolute[j, v]))
                for v in range(len(variables))
                if plain[j, v] or absolute[j, v]
            ]
            per_term.append([factor_index.setdefault(key, len(factor_index) + 1) for key in keys])
        self.k = max([len(f) for f in per_term] + [1])
        self.index = np.zeros((self.k, len(terms)), dtype=int)  # 0 = the column of ones
        for j, factors in enumerate(per_term):
            self.index[: len(factors), j] = factors
        keys = sorted(factor_index, key=lambda key: factor_index[key])
        self.factor_variable = np.array([-1] + [key[0] for key in keys])
        self.factor_plain = np.array([0] + [key[1] for key in keys])
        self.factor_absolute = np.array([0] + [key[2] for key in keys])
        self.max_plain = int(self.factor_plain.max(initial=0))
        self.max_absolute = int(self.factor_absolute.max(initial=0))
        variable_of = self.factor_variable[self.index]  # (K, p), -1 where padding
        # a term has at most one factor per variable: dg_j/dx_v is the derivative of the factor in
        # slot k of term j times the other factors, where v is that factor's variable (0 for other
        # variables)
        self.targets = [
            (variable_of[k][variable_of[k] >= 0], np.flatnonzero(variable_of[k] >= 0))
            for k in range(self.k)
        ]

    @cached_property
    def _flat(self) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Flat column indices into the (N, 2 x n_vars x h) power table (x powers, then |x|
        powers), h - 1 the highest power: each factor's x^a and |x|^b columns, then those of
        x^(a-1) and
        |x|^(b-1).
        """
        h = max(self.max_plain, self.max_absolute) + 1
        var = np.maximum(self.factor_variable, 0)
        a, b = self.factor_plain, self.factor_absolute
        offset = len(self.variables) * h
        return (
            h,
            np.concatenate([var * h + a, offset + var * h + b]),
            np.concatenate(
                [var * h + np.maximum(a - 1, 0), offset + var * h + np.maximum(b - 1, 0)]
            ),
            var,
            a.astype(float),
            b.astype(float),
        )

    @overload
    def _tables(
        self, values: np.ndarray, derivative: Literal[False]
    ) -> tuple[np.ndarray, None]: ...
    @overload
    def _tables(
        self, values: np.ndarray, derivative: Literal[True]
    ) -> tuple[np.ndarray, np.ndarray]: ...
    def _tables(
        self, values: np.ndarray, derivative: bool
    ) -> tuple[np.ndarray, np.ndarray | None]:
        h, at, down_at, var, a, b = self._flat
        n, m = values.shape
        powers = np.empty((n, 2, m, h))  # [1, x, x², ...] and [1, |x|, |x|², ...] per variable
        powers[..., 0] = 1.0
        if h > 1:
            powers[:, 0, :, 1] = values
            np.abs(values, out=powers[:, 1, :, 1])
        for k in range(2, h):
            np.multiply(powers[..., k - 1], powers[..., 1], out=powers[..., k])
        flat = powers.reshape(n, -1)  # x powers in the first m·h columns, |x| powers after
        f = len(var)
        parts = flat[:, at]
        x_part, a_part = parts[:, :f], parts[:, f:]
        table = x_part * a_part
        table[:, 0] = 1.0
        if not derivative:
            return table, None
        down = flat[:, down_at]
        d_table = a * down[:, :f] * a_part + b * x_part * down[:, f:] * np.sign(values)[:, var]
        d_table[:, 0] = 0.0
        return table, d_table

    def design(self, values: np.ndarray) -> np.ndarray:
        table, _ = self._tables(values, False)
        result: np.ndarray = table[:, self.index[0]]
        for k in range(1, self.k):
            result = result * table[:, self.index[k]]
        return result

    def design_and_derivatives(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """G (N, p) and dg/dx_v stacked as (n_vars, N, p)."""
        table, d_table = self._tables(values, True)
        gathered = [table[:, self.index[k]] for k in range(self.k)]
        design = gathered[0]
        for g in gathered[1:]:
            design = design * g
        derivatives = np.zeros((len(self.variables), values.shape[0], self.n_terms))
        for k in range(self.k):
            part = d_table[:, self.index[k]]
            for other in range(self.k):
                if other != k:
                    part = part * gathered[other]
            variable, term = self.targets[k]
            derivatives[variable, :, term] = part[:, term].T
        return design, derivatives


@dataclass(frozen=True)
class IterativeModel:
    """outputs (N, n_inputs) = g(loads) (N, n_terms) @ coefficients.T, coefficients (n_inputs,
    n_terms).

    `components` are the load names the terms use; `inputs` the bridge outputs. `loads` inverts by
    Newton iteration (R-091's iterative method), vectorised over samples.
    """

    name: str
    terms: tuple[Term, ...]
    coefficients: np.ndarray
    components: tuple[str, ...]
    inputs: tuple[str, ...]
    metadata: Mapping[str, Any] = field(default_factory=dict)
    tolerance: float = 1e-10  # Newton stops at |Δload| below this x the load scale
    max_iterations: int = 40

    form = 'iterative'
    extra_variables: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        coefficients = np.asarray(self.coefficients, dtype=float)
        if coefficients.shape != (len(self.inputs), len(self.terms)):
            raise ValueError(
                f'model {self.name}: coefficients have shape {coefficients.shape}, expected '
                f'{(len(self.inputs), len(self.terms))} (outputs x terms)'
            )
        if not np.all(np.isfinite(coefficients)):
            raise ValueError(f'model {self.name}: coefficients contain NaN or infinity')
        if len(self.inputs) != len(self.components):
            raise ValueError(
                f'model {self.name}: the iterative method needs as many outputs as loads '
                f'({len(self.inputs)} outputs, {len(self.components)} loads)'
            )
        unknown = sorted({v for t in self.terms for v in t.variables} - set(self.components))
        if unknown:
            raise ValueError(f'model {self.name}: terms use {", ".join(unknown)}, not a load')
        if any(t.is_constant for t in self.terms):
            raise ValueError(
                f'model {self.name}: an iterative model has no constant term '
                f'(outputs are measured from the natural zero)'
            )
        coefficients.setflags(write=False)
        object.__setattr__(self, 'coefficients', coefficients)

    @cached_property
    def term_names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.terms)

    @property
    def _exponents(self) -> NoReturn:
        # BalanceModel's polynomial shortcut (loads = coefficients · terms(outputs)) does not exist
        # for outputs = f(loads): say so instead of letting a fast path compute wrong loads
        raise AttributeError(
            f'model {self.name} is an iterative (R-091) model: loads come from model.loads() '
            f'(Newton), not from a polynomial of the outputs'
        )

    @cached_property
    def evaluator(self) -> TermEvaluator:
        return TermEvaluator(self.terms, self.components)

    @cached_property
    def linear_matrix(self) -> np.ndarray:
        """(n_inputs, n_components): coefficients of the plain first-degree terms (the starting
        point).
        """
        matrix = np.zeros((len(self.inputs), len(self.components)))
        for j, term in enumerate(self.terms):
            if term.degree == 1 and not term.factors[0].absolute:
                matrix[:, self.components.index(term.factors[0].variable)] = self.coefficients[
                    :, j
                ]
        return matrix

    @cached_property
    def linear_inverse(self) -> np.ndarray:
        """(n_components, n_inputs) inverse of the linear part: Newton's starting point."""
        return np.linalg.inv(self.linear_matrix)

    @cached_property
    def step_tolerance(self) -> np.ndarray:
        """(n_components,) Newton has converged for a sample once every load step is below this."""
        return self.tolerance * self.load_scale

    @cached_property
    def load_scale(self) -> np.ndarray:
        """(n_components,) a typical load, for the convergence test: capacities if known, else
        1.
        """
        capacity = self.metadata.get('capacity') if isinstance(self.metadata, Mapping) else None
        if capacity is not None and len(capacity) == len(self.components):
            return np.abs(np.asarray(capacity, np.float64))
        return np.ones(len(self.components))

    # --- forward: loads -> outputs ------------------------------------------------------------
    def design(self, loads: ArrayLike) -> np.ndarray:
        return self.evaluator.design(np.atleast_2d(np.asarray(loads, float)))

    def outputs(self, loads: ArrayLike) -> np.ndarray:
        """Outputs (N, n_inputs) the balance gives under total loads (N, n_components)."""
        outputs: np.ndarray = self.design(loads) @ self.coefficients.T
        return outputs

    def output_jacobian(self, loads: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(outputs (N, n_in), d outputs / d loads (N, n_in, n_components))."""
        design, jac = self.design_and_output_jacobian(loads)
        return design @ self.coefficients.T, jac

    def design_and_output_jacobian(self, loads: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(g(loads) (N, n_terms), d outputs / d loads (N, n_in, n_components))."""
        design, derivatives = self.evaluator.design_and_derivatives(
            np.atleast_2d(np.asarray(loads, float))
        )
        return design, np.moveaxis(derivatives @ self.coefficients.T, 0, -1)

    # --- inverse: outputs -> loads (the BalanceModel interface) ---------------------------------
    def loads(
        self, bridge_outputs_mv: ArrayLike, extra: Mapping[str, np.ndarray] | None = None
    ) -> np.ndarray:
        """Loads (N, n_components) from outputs (N, n_inputs) by Newton iteration.

        Raises InverseDidNotConverge naming the first sample that did not converge.
        """
        single = np.ndim(bridge_outputs_mv) == 1
        outputs = np.atleast_2d(np.asarray(bridge_outputs_mv, dtype=float))
        loads, converged = self.loads_and_status(outputs)
        if not converged.all():
            bad = np.flatnonzero(~converged)
            raise InverseDidNotConverge(
                f'model {self.name}: Newton iteration for the loads did not converge in '
                f'{self.max_iterations} steps for {bad.size} of {len(outputs)} sample(s), first '
                f'at sample {bad[0]} (outputs {np.round(outputs[bad[0]], 6).tolist()}); outside '
                'the calibrated range?'
            )
        return loads[0] if single else loads

    def loads_and_status(self, bridge_outputs_mv: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(loads (N, n_components), converged (N,) bool) by Newton iteration, vectorised over
        samples, without raising: a sample whose iteration did not converge gets a NaN row and
        converged False (the live calibrator publishes nothing for it and counts it). Non-finite
        outputs: NaN rows, converged True (nothing to iterate; the caller rejects them).
        """
        outputs = np.atleast_2d(np.asarray(bridge_outputs_mv, dtype=float))
        if outputs.shape[1] != len(self.inputs):
            raise ValueError(
                f'expected {len(self.inputs)} columns ({", ".join(self.inputs)}), got '
                f'{outputs.shape[1]}'
            )
        finite = np.all(np.isfinite(outputs), axis=1)
        outputs_used = np.where(finite[:, None], outputs, 0.0)
        try:
            loads = outputs_used @ self.linear_inverse.T
        except np.linalg.LinAlgError:
            raise InverseDidNotConverge(
                f'model {self.name}: the linear part is singular'
            ) from None
        scale = self.step_tolerance
        # Newton with the Jacobian refreshed every few steps (a chord method in between): the
        # Jacobian at the linear estimate already holds the balance's curvature, so the chord
        # steps converge in a few design evaluations each. Per sample: a sample stops iterating
        # once its own step is below the tolerance, so its loads do not depend on the other
        # samples of the batch (one sample alone gives the same numbers as within a batch).
        converged = np.zeros(len(outputs), dtype=bool)
        todo = np.arange(len(outputs))
        current, target, inverse = loads, outputs_used, None
        coefficients_t = self.coefficients.T
        with np.errstate(invalid='ignore', over='ignore', divide='ignore'):
            for iteration in range(self.max_iterations):
                if iteration % 6 == 0:
                    predicted, jac = self.output_jacobian(current)
                    try:
                        inverse = np.linalg.inv(jac)
                    except np.linalg.LinAlgError:
                        inverse = np.linalg.pinv(jac)
                else:
                    predicted = self.evaluator.design(current) @ coefficients_t
                step = (inverse @ (target - predicted)[:, :, None])[:, :, 0]
                current = current + step
                done = (np.abs(step) <= scale).all(axis=1)  # NaN steps never converge
                if done.all():
                    loads[todo], converged[todo], todo = current, True, todo[:0]
                    break
                if done.any():
                    loads[todo[done]], converged[todo[done]] = current[done], True
                    keep = ~done
                    todo, current, target = todo[keep], current[keep], target[keep]
                    inverse = cast(np.ndarray, inverse)[keep]  # set at iteration 0
        if todo.size:
            loads[todo] = np.nan
        if finite.all():
            return loads, converged
        loads[~finite] = np.nan
        return loads, converged | ~finite

    def jacobian(
        self, bridge_outputs_mv: ArrayLike, extra: Mapping[str, np.ndarray] | None = None
    ) -> np.ndarray:
        """D loads / d outputs (N, n_components, n_inputs): the inverse of d outputs / d loads."""
        loads = np.atleast_2d(self.loads(bridge_outputs_mv, extra))
        _, jac = self.output_jacobian(loads)
        return np.linalg.inv(jac)

    def without_constant(self) -> 'IterativeModel':
        return self  # no constant term (TM-663 §10.1 holds already)

    def with_metadata(self, **metadata: Any) -> 'IterativeModel':
        return replace(self, metadata={**self.metadata, **metadata})

    # --- files --------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            'name': self.name,
            'form': 'iterative',
            'components': list(self.components),
            'inputs': list(self.inputs),
            'terms': list(self.term_names),
            'output_coefficients': {
                c: [float(x) for x in row] for c, row in zip(self.inputs, self.coefficients)
            },
            **({'metadata': _plain(self.metadata)} if self.metadata else {}),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = 'model') -> 'IterativeModel':
        try:
            terms = parse_terms(data['terms'])
            components = tuple(data['components'])
            inputs = tuple(data['inputs'])
            rows = data['output_coefficients']
            missing = [c for c in inputs if c not in rows]
            if missing:
                raise ValueError(f'no output_coefficients for {", ".join(missing)}')
            coefficients = np.array([[float(x) for x in rows[c]] for c in inputs])
            if coefficients.shape[1] != len(terms):
                raise ValueError(
                    f'{coefficients.shape[1]} coefficients per output but {len(terms)} terms'
                )
            return cls(
                str(data.get('name', 'iterative')),
                terms,
                coefficients,
                components,
                inputs,
                dict(data.get('metadata') or {}),
            )
        except KeyError as err:
            raise ValueError(f'{where}: missing key {err.args[0]!r}') from None
        except (TypeError, ValueError) as err:
            raise ValueError(f'{where}: {err}') from None
