"""General term machinery: a model is a list of terms, each a product of powers of named variables.

A term is written as a name that a person can read and a YAML file can hold:

    "1"              the constant (TM-663's C1, C8, ... in eqs. (1)-(18))
    "FXV"            a bridge output, mV
    "FXV^2"          a square (the memo's tables write FXV*FXV on the diagonal, and parse to this)
    "FZV*MZV"        an interaction
    "FXV^3"          a cube (the memo prints MXV^3 as ELV**3, and so on)
    "|FXV|"          absolute value (AIAA R-091's sign-dependent terms)
    "FXV*|FXV|"      sign-dependent curvature
    "dT", "dT*FXV"   any other named variable: temperature difference, time, load direction...

Variables are looked up by name in a mapping of equal-length arrays, so the same machinery serves
six bridges, six bridges plus temperature, or the one channel of a thrust stand.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache
import re
from typing import Iterable, Mapping, Sequence

import numpy as np

_FACTOR_RE = re.compile(r'^(\|?)([A-Za-z_][A-Za-z0-9_]*)(\|?)(?:\^(\d+))?$')


@dataclass(frozen=True, order=True)
class Factor:
    """One variable raised to a positive integer power, optionally of its absolute value."""

    variable: str
    power: int = 1
    absolute: bool = False

    @property
    def name(self) -> str:
        base = f'|{self.variable}|' if self.absolute else self.variable
        return base if self.power == 1 else f'{base}^{self.power}'

    def evaluate(self, value: np.ndarray) -> np.ndarray:
        base = np.abs(value) if self.absolute else value
        return base**self.power

    def derivative(self, value: np.ndarray) -> np.ndarray:
        """d(factor)/d(variable), elementwise."""
        if self.absolute:
            slope: np.ndarray = self.power * np.abs(value) ** (self.power - 1) * np.sign(value)
            return slope
        return self.power * value ** (self.power - 1)


@dataclass(frozen=True)
class Term:
    """A product of factors; the empty product is the constant term "1"."""

    factors: tuple[Factor, ...] = ()

    @classmethod
    def parse(cls, name: str) -> 'Term':
        """Parse a term name ("1", "FXV", "FXV*FXV", "FXV^3", "dT*|FYV|"); raises ValueError.

        A name already parsed returns the same (immutable) Term: the diagnosis parses the same
        few hundred names thousands of times a refit.
        """
        return _parsed_term(name) if cls is Term else cls._parse(name)

    @classmethod
    def _parse(cls, name: str) -> 'Term':
        """The Term a name reads as (Term.parse without its cache); raises ValueError."""
        text = name.replace(' ', '').replace('**', '^')
        if text in ('1', ''):
            return cls(())
        powers: dict[tuple[str, bool], int] = {}
        order: list[tuple[str, bool]] = []
        for part in text.split('*'):
            match = _FACTOR_RE.match(part)
            if not match or (match.group(1) != match.group(3)):
                raise ValueError(f'cannot read term {name!r}: bad factor {part!r}')
            key = (match.group(2), bool(match.group(1)))
            if key not in powers:
                order.append(key)
                powers[key] = 0
            powers[key] += int(match.group(4) or 1)
        return cls(
            tuple(Factor(var, powers[(var, absolute)], absolute) for var, absolute in order)
        )

    @cached_property
    def name(self) -> str:
        return '*'.join(f.name for f in self.factors) if self.factors else '1'

    @cached_property
    def variables(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(f.variable for f in self.factors))

    @property
    def degree(self) -> int:
        return sum(f.power for f in self.factors)

    @property
    def is_constant(self) -> bool:
        return not self.factors

    def evaluate(self, variables: Mapping[str, np.ndarray], length: int) -> np.ndarray:
        column = np.ones(length)
        for factor in self.factors:
            column = column * factor.evaluate(np.asarray(variables[factor.variable], dtype=float))
        return column

    def derivative(
        self, variable: str, variables: Mapping[str, np.ndarray], length: int
    ) -> np.ndarray:
        """d(term)/d(variable) by the product rule, elementwise."""
        total = np.zeros(length)
        for i, factor in enumerate(self.factors):
            if factor.variable != variable:
                continue
            part = factor.derivative(np.asarray(variables[variable], dtype=float))
            for j, other in enumerate(self.factors):
                if j != i:
                    part = part * other.evaluate(
                        np.asarray(variables[other.variable], dtype=float)
                    )
            total = total + part
        return total

    def __str__(self) -> str:
        return self.name


@lru_cache(maxsize=4096)
def _parsed_term(name: str) -> Term:
    """Term._parse(name), kept for the next time the name is read."""
    return Term._parse(name)


def parse_terms(names: Iterable[str]) -> tuple[Term, ...]:
    terms = tuple(Term.parse(n) for n in names)
    seen: dict[str, int] = {}
    for i, term in enumerate(terms):
        if term.name in seen:
            raise ValueError(
                f'term {term.name} appears twice (positions {seen[term.name] + 1} and {i + 1})'
            )
        seen[term.name] = i
    return terms


def as_variables(
    names: Sequence[str], values: np.ndarray, extra: Mapping[str, np.ndarray] | None = None
) -> dict[str, np.ndarray]:
    """Named columns from an (N, len(names)) array, plus any extra named (N,) arrays."""
    values = np.atleast_2d(np.asarray(values, dtype=float))
    if values.shape[1] != len(names):
        raise ValueError(
            f'expected {len(names)} columns ({", ".join(names)}), got {values.shape[1]}'
        )
    variables = {name: values[:, i] for i, name in enumerate(names)}
    for key, column in (extra or {}).items():
        variables[key] = np.broadcast_to(np.asarray(column, dtype=float), (values.shape[0],))
    return variables


def term_exponents(terms: Sequence[Term], names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Powers (n_terms, n_vars) of each variable in each term: of its value, and of its absolute
    value.
    """
    plain = np.zeros((len(terms), len(names)), dtype=np.int64)
    absolute = np.zeros_like(plain)
    for j, term in enumerate(terms):
        for factor in term.factors:
            (absolute if factor.absolute else plain)[j, list(names).index(factor.variable)] += (
                factor.power
            )
    return plain, absolute


def power_products(
    values: np.ndarray, plain: np.ndarray, absolute: np.ndarray | None
) -> np.ndarray:
    """(N, n_terms) = prod_v values[:, v] ** plain[:, v] * |values[:, v]| ** absolute[:, v]."""
    # np.multiply.reduce is np.prod without its Python wrapper (a lone live sample pays per call)
    matrix: np.ndarray = np.multiply.reduce(np.power(values[:, None, :], plain), axis=2)
    if absolute is not None and absolute.any():
        matrix = matrix * np.multiply.reduce(
            np.power(np.abs(values)[:, None, :], absolute), axis=2
        )
    return matrix


def design_matrix(
    terms: Sequence[Term], variables: Mapping[str, np.ndarray], length: int
) -> np.ndarray:
    """(N, n_terms) matrix whose column j is term j evaluated on every sample."""
    missing = sorted({v for t in terms for v in t.variables} - set(variables))
    if missing:
        raise KeyError(
            f'the model needs variable(s) {", ".join(missing)} that the data does not have'
        )
    names = tuple(dict.fromkeys(v for t in terms for v in t.variables))
    values = (
        np.column_stack(
            [np.broadcast_to(np.asarray(variables[v], dtype=float), (length,)) for v in names]
        )
        if names
        else np.zeros((length, 0))
    )
    return power_products(values, *term_exponents(terms, names))
