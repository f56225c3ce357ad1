"""The search's state (diagnose.py): design columns by term name (_Problem), one component's fits,
a family's candidate, and SearchState, what the examinations and the leftovers read.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..fit.least_squares import LeastSquares
from ..fit.svd import orthonormal_columns
from ..model.terms import parse_terms
from ..tare.calibration_body import CorrectedData
from .settings import DiagnosisSettings
from .statistics import fit_columns, ZeroPointWhitening
from .tare_refit import BodyRefit


# --- the search -------------------------------------------------------------------------------
class _Problem:
    """Design columns by term name over the corrected data, plain and whitened.

    Least squares over all points (eq. (19)) gives the coefficients, σ and PRESS; the tests use
    the same fit whitened against the zero-point noise (statistics.ZeroPointWhitening).
    """

    def __init__(
        self,
        outputs_names,
        corrected: CorrectedData,
        variables,
        whitening: ZeroPointWhitening,
        components=(),
        times=None,
        gravity=None,
    ):
        self.outputs_names = tuple(outputs_names)
        self.gravity = None if gravity is None else np.asarray(gravity, dtype=float)
        self.times = None if times is None else np.asarray(times, dtype=float)
        self.components = tuple(components)
        self.variables = variables
        self.whiten = whitening
        self.n_white = int(whitening.loaded.sum())
        self.set_corrected(corrected)

    def set_corrected(self, corrected: CorrectedData):
        self.corrected = corrected
        self.outputs = np.asarray(corrected.bridge_outputs_mv, dtype=float)
        self.loads = np.asarray(corrected.loads, dtype=float)
        self.loads_white = self.whiten(self.loads)
        # the columns computed so far, plain and whitened, side by side: index[name] is a
        # term's column in both (room for more kept at the right)
        self.index: dict[str, int] = {}
        self.store = np.empty((len(self.outputs), 0))
        self.store_white = np.empty((self.n_white, 0))

    def _add(self, names: Sequence[str]) -> None:
        """Compute the columns of the names not yet in the store and keep them there."""
        missing = [n for n in dict.fromkeys(names) if n not in self.index]
        if not missing:
            return
        # term by term (a product of a few factors): the general design_matrix raises every
        # variable to every term's power, which costs N x terms x variables with the hundreds
        # of time-basis variables here
        outputs = {name: self.outputs[:, i] for i, name in enumerate(self.outputs_names)}
        matrix = np.ones((len(self.outputs), len(missing)))
        for j, term in enumerate(parse_terms(missing)):
            for factor in term.factors:
                value = (
                    outputs[factor.variable]
                    if factor.variable in outputs
                    else self.variables[factor.variable]
                )
                matrix[:, j] *= factor.evaluate(np.asarray(value, dtype=float))
        white = self.whiten(matrix)
        used = len(self.index)
        if used + len(missing) > self.store.shape[1]:
            room = max(2 * (used + len(missing)), 64)
            self.store = _widened(self.store, used, room)
            self.store_white = _widened(self.store_white, used, room)
        self.store[:, used : used + len(missing)] = matrix
        self.store_white[:, used : used + len(missing)] = white
        for j, name in enumerate(missing):
            self.index[name] = used + j

    def columns(self, names: Sequence[str]) -> np.ndarray:
        """(N, len(names)) the terms' columns over all points (a new array)."""
        self._add(names)
        return self._taken(self.store, names)

    def white_columns(self, names: Sequence[str]) -> np.ndarray:
        """(N_loaded, len(names)) the terms' whitened columns over the loaded points (a new
        array).
        """
        self._add(names)
        return self._taken(self.store_white, names)

    def _taken(self, store: np.ndarray, names: Sequence[str]) -> np.ndarray:
        """The names' columns of store, C-contiguous as np.column_stack made them (the products
        with them round the same).
        """
        if not names:
            return np.zeros((store.shape[0], 0))
        return np.take(store, [self.index[n] for n in names], axis=1)

    def white_residuals(self, terms_per_component: Sequence[Sequence[str]]) -> list[np.ndarray]:
        """Whitened residuals of every component; one QR per distinct term list."""
        groups: dict[tuple, list[int]] = {}
        for k, terms in enumerate(terms_per_component):
            groups.setdefault(tuple(terms), []).append(k)
        residuals: list = [None] * len(terms_per_component)
        for terms, ks in groups.items():
            matrix = self.white_columns(list(terms))
            scaled = matrix / np.maximum(np.linalg.norm(matrix, axis=0), 1e-300)
            q = orthonormal_columns(scaled, 1e-9)
            targets = self.loads_white[:, ks]
            fitted = targets - q @ (q.T @ targets)
            for i, k in enumerate(ks):
                residuals[k] = fitted[:, i]
        return residuals

    def fit(self, k: int, terms: Sequence[str]) -> '_Fit':
        return _Fit(
            fit_columns(self.columns(terms), self.loads[:, k]),
            fit_columns(self.white_columns(terms), self.loads_white[:, k]),
        )


def _widened(store: np.ndarray, used: int, columns: int) -> np.ndarray:
    """A (rows, columns) array holding store's first `used` columns."""
    wider = np.empty((store.shape[0], columns))
    wider[:, :used] = store[:, :used]
    return wider


@dataclass(frozen=True)
class _Fit:
    ols: LeastSquares  # all points, eq. (19): coefficients, σ, PRESS
    gls: LeastSquares  # loaded points, whitened: the tests


@dataclass
class _Candidate:
    family: str
    components: dict  # component index -> dict of statistics
    score: float
    body_refit: BodyRefit | None = None
    components_fits: list | None = None  # tare: every component refitted with the new body


@dataclass
class SearchState:
    """What the search has so far, in one value: the family examinations, the tare, the re-read
    and the leftovers read it instead of a dozen loose arguments.

    fits and comp_terms are per component and change as the search adopts terms (diagnose());
    base_fits and base_terms are those of the base model; the rest is fixed for one diagnosis.
    """

    problem: _Problem  # design columns over the corrected data (its components and outputs)
    fits: list  # [_Fit] per component, the current model
    comp_terms: list  # [[term name]] per component, the current model
    base_fits: list  # [_Fit] per component, the base model
    base_terms: list  # term names of the base model
    settings: DiagnosisSettings
    capacity: np.ndarray  # (6,) N / N·m
    variables: dict  # name -> (N,) values of the extra variables the families' terms use
    points: Any  # the reduction's points (LoadPoints)
    direction: np.ndarray  # (N, 6) raw ±1 load history
    times: np.ndarray  # (N,) s
    temps: np.ndarray  # (N,) °C (NaN where unknown)
    point_variance_mv2: Any = None  # (P, 6) or None, see diagnose()
    point_samples: Any = None  # (P,) or None

    @property
    def components(self) -> tuple[str, ...]:
        return self.problem.components

    @property
    def outputs_names(self) -> tuple[str, ...]:
        return self.problem.outputs_names
