"""Choosing the math model of a table calibration by what its data support (R-091/BALFIT practice).

Candidates are the model forms asked for (direct: loads from outputs, TM-663; iterative: outputs
from loads, R-091) times the term sets (linear, TM-663 quadratic and cubic, R-091's 96 terms, and a
`--terms FILE`), each restricted to the terms the schedule determines (term_screen.py). Every
candidate is fitted with its series tares and judged by its cross-validated σ (PRESS, leave one
point out) per load, in % of capacity. Per form the candidate of lowest mean cross-validated σ is
kept among those no worse than the form's linear model on any load (beyond the chance scatter
of a cross-validated σ, two standard errors); its terms are then pruned by
PRESS (a term goes when leaving it out lowers the mean log PRESS over the targets, hierarchy kept:
never a factor of a product that stays, never a linear term), and the pruned model replaces it only
when it is again no worse than the linear model on any load and better on average. Between the
forms `choose_form` decides (calibrate.py's rule, unchanged).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast, Mapping, Sequence

import numpy as np

from ..accuracy.sigma import sigma_pct_fs
from ..fit.iterative import fit_iterative, IterationDidNotConverge
from ..fit.least_squares import TooFewPointsError, UnexcitedTermsError
from ..fit.series_tares import fit_direct, series_indicator, SeriesTareFit
from ..fit.term_selection import elimination_step, term_statistics
from ..model.inverse import InverseDidNotConverge
from ..model.r091 import term_set, TermEvaluator
from ..model.terms import Term
from ..model.tm663 import tm663_terms
from .errors import TableCalibrationError
from .table_report import normality
from .term_screen import screen_for_table

AUTO_TERM_SETS = ('linear', 'tm663-quadratic', 'tm663-cubic', 'r091-96')
FIT_ERRORS = (
    UnexcitedTermsError,
    TooFewPointsError,
    IterationDidNotConverge,
    InverseDidNotConverge,
)
MAX_REMOVALS = 60
# each form's default set (TM-663's cubic; R-091's 96 terms) stays unless another candidate, or the
# pruned model, lowers the mean cross-validated σ by more than this fraction: the scatter of a
# cross-validated σ from N points is about 1/sqrt(2N) of it (4 % at 300 points, 6 loads averaged
# 1.6 %), and a smaller gain is as likely chance as a better model
DEFAULT_SETS = {'direct': 'tm663-cubic', 'iterative': 'r091-96'}
SELECTION_MARGIN = 0.03


@dataclass(frozen=True)
class Candidate:
    method: str
    term_set: str
    terms: tuple[Term, ...]
    dropped: tuple[tuple[str, str], ...]  # by the schedule screen
    fit: SeriesTareFit | None
    crossval: np.ndarray | None  # (n_loads,) % capacity
    error: str = ''

    @property
    def score(self) -> float:
        return float(np.mean(self.crossval)) if self.crossval is not None else np.inf


@dataclass(frozen=True)
class FormChoice:
    """The model adopted for one form, with what was compared and removed on the way."""

    candidate: Candidate
    removed: tuple[tuple[str, str], ...] = ()  # by PRESS: (term, why)
    compared: tuple[Candidate, ...] = field(default_factory=tuple)
    why: str = ''


def terms_for(spec: str, method: str, table) -> tuple[Term, ...]:
    """The term set `spec` in the form's variables (direct: outputs; iterative: loads)."""
    variables, other = (
        (table.bridge_symbols, table.load_symbols)
        if method == 'direct'
        else (table.load_symbols, table.bridge_symbols)
    )
    if spec in ('linear', 'tm663-quadratic'):
        order = 'linear' if spec == 'linear' else 'quadratic'
        return tuple(t for t in tm663_terms(order, tuple(variables)) if not t.is_constant)
    return term_set(spec, variables, other)


def crossval_pct(fit: SeriesTareFit, capacity: np.ndarray) -> np.ndarray:
    """(n_loads,) RMS of the leave-one-out load residuals, % of capacity."""
    return np.atleast_1d(sigma_pct_fs(fit.press_load_residuals, capacity))  # TM-663 eq. (44)


def fit_form(
    method: str, terms: Sequence[Term], table, outputs: np.ndarray, *, statistics: bool = False
) -> SeriesTareFit:
    """One form fitted with the table's series tares (SI loads)."""
    if method == 'direct':
        return fit_direct(
            terms,
            outputs,
            table.applied_loads_si,
            table.series,
            components=table.load_symbols,
            inputs=table.bridge_symbols,
            name='direct',
            statistics=statistics,
        )
    return fit_iterative(
        terms,
        table.applied_loads_si,
        outputs,
        table.series,
        components=table.load_symbols,
        inputs=table.bridge_symbols,
        capacity=table.load_capacity_si,
        statistics=statistics,
    )


def candidate(method: str, spec: str, table, outputs: np.ndarray, *, strict: bool) -> Candidate:
    """Screen, fit and cross-validate one form x term set; strict: a fit failure is raised."""
    try:
        terms = terms_for(spec, method, table)
    except ValueError as err:
        raise TableCalibrationError(str(err)) from None
    screen = screen_for_table(method, terms, table, outputs)
    try:
        fit = fit_form(method, screen.kept, table, outputs)
    except FIT_ERRORS as err:
        if strict:
            raise TableCalibrationError(f'{table.source}: {err}') from None
        return Candidate(method, spec, screen.kept, screen.dropped, None, None, str(err))
    return Candidate(
        method, spec, screen.kept, screen.dropped, fit, crossval_pct(fit, table.load_capacity_si)
    )


def _no_worse(crossval: np.ndarray, reference: np.ndarray, points: int) -> bool:
    """No load's cross-validated σ worse than the reference's beyond chance: two standard errors
    of a σ estimated from N points (relative standard error 1/sqrt(2N)).
    """
    return bool(np.all(crossval <= reference * (1.0 + 2.0 / np.sqrt(2.0 * points))))


def _linear_problem(method: str, fit: SeriesTareFit, terms, table, outputs):
    """(design (N, p + n_series), targets) of the fitted form with its tares held."""
    _, index, onehot = series_indicator(table.series)
    if method == 'direct':
        design = TermEvaluator(terms, table.bridge_symbols).design(outputs)
        return np.hstack([design, -onehot]), table.applied_loads_si
    totals = table.applied_loads_si + fit.tares[index]
    return np.hstack([TermEvaluator(terms, table.load_symbols).design(totals), onehot]), outputs


def with_statistics(
    method: str, fit: SeriesTareFit, terms: Sequence[Term], table, outputs: np.ndarray
) -> SeriesTareFit:
    """The fit with its term statistics (VIF, p, PRESS per term), from the same linear problem
    fit_direct / fit_iterative solve at the fitted tares: no second Gauss-Newton.
    """
    from dataclasses import replace

    from ..fit.series_tares import solve_scaled

    design, targets = _linear_problem(method, fit, terms, table, outputs)
    names = [t.name for t in terms]
    columns = names + [f'series {s}' for s in fit.series_labels]
    solution = solve_scaled(design, targets, columns, method)
    targets_names = list(table.load_symbols if method == 'direct' else table.bridge_symbols)
    stats = term_statistics(
        design,
        targets,
        solution.coefficients,
        solution.covariance_unscaled,
        len(terms),
        names,
        targets_names,
    )
    return replace(fit, statistics=stats)


def _removable(terms: Sequence[Term], j: int) -> bool:
    term = terms[j]
    if term.degree == 1 and not term.factors[0].absolute:
        return False
    if len(term.variables) == 1 and len(term.factors) == 1:
        part = term.factors[0]
        for other in terms:  # a factor of a product that stays
            if len(other.variables) > 1 and part in other.factors:
                return False
    return True


def prune_by_press(
    method: str, fit: SeriesTareFit, terms: Sequence[Term], table, outputs: np.ndarray
) -> tuple[tuple[Term, ...], tuple[tuple[str, str], ...]]:
    """Backward elimination on the form's linear problem by the closed-form PRESS of each term
    (fit/term_selection.elimination_step), hierarchy kept; returns (terms kept, [(term, why)]).
    """
    terms = list(terms)
    design, targets = _linear_problem(method, fit, terms, table, outputs)
    nuisance = design[:, len(terms) :]
    columns = design[:, : len(terms)]
    removed: list[tuple[str, str]] = []
    n = len(targets)
    while len(removed) < MAX_REMOVALS and len(terms) > 1:
        stats = elimination_step(
            np.hstack([columns, nuisance]),
            targets,
            len(terms),
            [t.name for t in terms],
            ['t'] * targets.shape[1],
            full_rank_only=True,
        )
        if stats is None:
            break
        score = np.mean(np.log(np.maximum(stats.press_ratio, 1e-300)), axis=1)
        allowed = [j for j in range(len(terms)) if _removable(terms, j) and score[j] < 0]
        if not allowed:
            break
        j = min(allowed, key=lambda i: score[i])
        q = len(terms) + nuisance.shape[1]
        removed.append(
            (
                terms[j].name,
                f'PRESS {100 * (np.exp(score[j]) - 1):+.2f} % without it '
                f'(mean over targets; {n / q:.1f} points per coefficient '
                f'before, {n / (q - 1):.1f} after)',
            )
        )
        del terms[j]
        columns = np.delete(columns, j, axis=1)
    return tuple(terms), tuple(removed)


def choose_within_form(
    method: str, specs: Sequence[str], table, outputs: np.ndarray, *, prune: bool = True
) -> FormChoice:
    """The best candidate of one form by cross-validated σ, then pruned by PRESS (`prune`)."""
    strict = len(specs) == 1
    compared = [candidate(method, spec, table, outputs, strict=strict) for spec in specs]
    # one screened term list may come from several sets (a small schedule): fit it once
    fitted = [c for c in compared if c.fit is not None]
    if not fitted:
        raise TableCalibrationError(
            f'{table.source}: no {method} model could be fitted: {compared[0].error}'
        )
    linear = next((c for c in fitted if c.term_set == 'linear'), None)
    reference = linear.crossval if linear is not None else None
    eligible = [
        c
        for c in fitted
        if reference is None or _no_worse(cast(np.ndarray, c.crossval), reference, table.points)
    ]
    best = min(eligible or fitted, key=lambda c: c.score)
    default = next((c for c in eligible if c.term_set == DEFAULT_SETS[method]), None)
    if default is not None and not best.score < (1 - SELECTION_MARGIN) * default.score:
        best = default
    best_fit = cast(SeriesTareFit, best.fit)  # a fitted candidate
    why = (
        f'{best.term_set} ({len(best.terms)} terms, '
        f'{table.points / (len(best.terms) + len(best_fit.series_labels)):.1f} points per '
        f'coefficient): mean cross-validated σ {best.score:.4g} % capacity'
    )
    if len(specs) == 1 or not prune:
        return FormChoice(best, (), tuple(compared), why)
    terms, removed = prune_by_press(method, best_fit, best.terms, table, outputs)
    if removed:
        try:
            pruned_fit = fit_form(method, terms, table, outputs)
        except FIT_ERRORS:
            pruned_fit = None
        if pruned_fit is not None:
            cv = crossval_pct(pruned_fit, table.load_capacity_si)
            if (reference is None or _no_worse(cv, reference, table.points)) and np.mean(cv) < (
                1 - SELECTION_MARGIN
            ) * best.score:
                pruned = Candidate(method, best.term_set, terms, best.dropped, pruned_fit, cv)
                why += (
                    f'; {len(removed)} term(s) removed by PRESS: mean cross-validated σ '
                    f'{np.mean(cv):.4g} %'
                )
                return FormChoice(pruned, removed, tuple(compared), why)
        removed = ()
    return FormChoice(best, removed, tuple(compared), why)


def terms_dropped(choice: FormChoice) -> list[dict]:
    """report.json terms_dropped of one form: every term a compared set lost to the schedule screen
    (its first reason), then those the PRESS pruning removed from the adopted model.
    """
    seen: dict[str, dict] = {}
    for c in choice.compared:
        for term, why in c.dropped:
            seen.setdefault(term, {'term': term, 'why': why, 'term_set': c.term_set})
    return list(seen.values()) + [
        {'term': t, 'why': w, 'term_set': choice.candidate.term_set} for t, w in choice.removed
    ]


def compared_entry(c: Candidate, symbols: Sequence[str]) -> dict:
    """One line of report.json model_selection.candidates."""
    entry = {'method': c.method, 'term_set': c.term_set, 'terms': len(c.terms)}
    if c.fit is None:
        entry['error'] = c.error
    else:
        entry['crossval'] = {
            s: round(float(v), 5) for s, v in zip(symbols, cast(np.ndarray, c.crossval))
        }
        entry['crossval_mean'] = round(c.score, 5)
    return entry


def choose_form(fits: Mapping[str, SeriesTareFit], capacity, symbols) -> tuple[str, str]:
    """Adopt the form with the lower mean cross-validated σ (% capacity); say why, with the
    residual structure.
    """
    cv = {m: crossval_pct(f, capacity) for m, f in fits.items()}
    score = {m: float(np.mean(v)) for m, v in cv.items()}
    structure, odd_count = [], {}
    for method, fit in fits.items():
        normal = normality(fit.load_residuals, symbols)
        odd = [f'{s} (p={p:.2g})' for s, p in normal.items() if p < 1e-3]
        odd_count[method] = len(odd)
        if odd:
            structure.append(f'{method} residuals non-normal on {", ".join(odd)}')
    chosen = min(score, key=lambda m: score[m])
    other = [m for m in fits if m != chosen][0]
    tie_break = ''
    # within 2 % on σ the residual structure decides: a form that leaves non-normal (structured)
    # residuals misses something the other captures
    if score[other] <= 1.02 * score[chosen] and odd_count[chosen] > odd_count[other]:
        chosen, other = other, chosen
        tie_break = (
            f'; σ within 2 %, so the form with fewer non-normal residual components '
            f'({odd_count[chosen]} against {odd_count[other]}) is adopted'
        )
    # within 2 %, alike in structure and not lower on every load (a sign test: 6 of 6 by chance
    # has p = 1/64) the data cannot tell the forms apart: TM-663's direct form (the one refit fits
    # and the live polynomial evaluates) is kept
    elif (
        chosen == 'iterative'
        and 'direct' in fits
        and score['direct'] <= 1.02 * score[chosen]
        and odd_count['direct'] == odd_count[chosen]
        and not np.all(cv['iterative'] < cv['direct'])
    ):
        chosen, other = 'direct', chosen
        tie_break = (
            f'; σ within 2 % and as many non-normal residual components '
            f"({odd_count[chosen]}), so TM-663's direct form is kept"
        )
    better = [s for s, a, b in zip(symbols, cv[chosen], cv[other]) if a < b]
    why = (
        f'{chosen}: cross-validated σ {score[chosen]:.4f} % capacity (mean over loads) against '
        f'{score[other]:.4f} % for {other}, lower on {len(better)} of {len(symbols)} loads '
        f'({", ".join(better) or "none"}){tie_break}'
    )
    if structure:
        why += '; ' + '; '.join(structure)
    return chosen, why


def select_terms(method: str, terms, fit: SeriesTareFit, table, outputs, loads_si):
    """Backward elimination by PRESS on the linear problem of a fitted form (its tares held)."""
    from ..fit.series_tares import series_indicator
    from ..fit.term_selection import backward_elimination
    from ..model.r091 import TermEvaluator

    _, index, onehot = series_indicator(table.series)
    names = [t.name for t in terms]
    linear = [t.name for t in terms if t.degree == 1 and not t.factors[0].absolute]
    if method == 'direct':
        design = np.hstack([TermEvaluator(terms, table.bridge_symbols).design(outputs), -onehot])
        targets, target_names = loads_si, table.load_symbols
    else:
        totals = loads_si + fit.tares[index]
        design = np.hstack([TermEvaluator(terms, table.load_symbols).design(totals), onehot])
        targets, target_names = outputs, table.bridge_symbols
    selection = backward_elimination(design, targets, len(terms), names, target_names, keep=linear)
    return tuple(t for t in terms if t.name in selection.kept), selection
