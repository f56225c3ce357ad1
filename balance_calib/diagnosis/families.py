"""The family examinations of one search round (diagnose.py): forward selection of a family's terms
per component, the size, cross-validation and constancy gates, excitation's joint selection.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..accuracy.sigma import sigma_pct_fs
from ..fit.least_squares import LeastSquares
from ..fit.svd import minimum_norm_solve
from ..model.terms import parse_terms
from .candidates import (
    CandidateFamily,
    own_terms_only,
    STATIC_FAMILIES,
)
from .search_state import _Candidate, _Fit, _Problem, SearchState
from .settings import DiagnosisSettings
from .statistics import fit_columns, forward_select, partial_f


def _component_statistics(before: _Fit, after: _Fit, capacity: float, n_tests: int) -> dict:
    n, n_white = before.ols.points, before.gls.points
    added = after.gls.rank - before.gls.rank
    f_value, p_value = partial_f(before.gls.rss, after.gls.rss, added, after.gls.dof)
    removed = np.sqrt(max(before.ols.rss - after.ols.rss, 0.0) / n) / capacity * 100.0
    ratio = before.gls.rss / after.gls.rss if after.gls.rss > 0 else 1.0
    return {
        'fit': after,
        'q': added,
        'f': f_value,
        'p': min(1.0, p_value * n_tests),
        'r': float(np.sqrt(max(1.0 - 1.0 / ratio, 0.0))),
        'removed': float(removed),
        'sigma_before': sigma_pct_fs(before.ols.residuals, capacity),
        'sigma_after': sigma_pct_fs(after.ols.residuals, capacity),
        'press_before': sigma_pct_fs(before.ols.press_residuals, capacity),
        'press_after': sigma_pct_fs(after.ols.press_residuals, capacity),
        'bic_gain': float(n_white * np.log(ratio) - added * np.log(n_white)),
    }


def _passes(stats: dict, settings: DiagnosisSettings, any_size: bool = False) -> bool:
    """The size gate (min_effect_pct_fs, unless any_size: see beside_its_partner) and a lower
    cross-validated σ.
    """
    return (any_size or stats['removed'] >= settings.min_effect_pct_fs) and stats[
        'press_after'
    ] < stats['press_before']


def _examine_family(family, state: SearchState, n_searches, any_size=frozenset()):
    """The family's candidate: the components where its terms pass (any_size: components where
    the size gate is waived, beside_its_partner).
    """
    fits, comp_terms, problem = state.fits, state.comp_terms, state.problem
    capacity, settings = state.capacity, state.settings
    accepted = {}
    n_components = len(fits)
    for k, fit in enumerate(fits):
        present = set(comp_terms[k])
        offered = own_terms_only(
            family, problem.components[k], problem.outputs_names[k], problem.components
        )
        groups = [g for g in offered if not set(g) & present]
        if not groups:
            continue
        names = [t for g in groups for t in g]
        index = {t: i for i, t in enumerate(names)}
        # Bonferroni within this family, weighted over its groups (shares sum to 1 a component)
        candidates = problem.white_columns(names)
        columns = [tuple(index[t] for t in g) for g in groups]
        shares = _level_shares(family, groups, candidates, columns, problem, k, settings)
        levels = settings.alpha * shares / (n_searches * n_components)
        selection = forward_select(
            fit.gls,
            candidates,
            columns,
            alpha_per_test=levels,
            max_groups=family.max_groups,
        )
        if not selection.steps:
            continue
        chosen = [groups[i] for i in selection.groups]
        offered = (candidates, columns, groups)
        if family.name == 'bidirectional':
            chosen = _settle_sign_shape(
                problem,
                k,
                comp_terms[k],
                fit,
                offered,
                selection.groups,
                settings,
                family,
            )
        elif family.name == 'hysteresis':
            chosen = _completed_at_lack_of_fit(
                problem, k, comp_terms[k], offered, chosen, settings, family.max_groups
            )
            chosen = _completed_while_moving(
                problem,
                k,
                comp_terms[k],
                fit,
                offered,
                chosen,
                settings,
                family,
            )
        added = [t for g in chosen for t in g]
        # the adjusted p of the first group taken: p x α / its level
        n_tests = settings.alpha / levels[selection.groups[0]]
        stats = _component_statistics(
            fit, problem.fit(k, comp_terms[k] + added), capacity[k], n_tests
        )
        label = family.label(chosen)
        if family.name == 'zero_drift':
            label = f'the time drift between zero points (periods {label.replace(" + ", ", ")})'
        stats.update(added=tuple(added), groups=tuple(chosen), label=label)
        if _passes(stats, settings, k in any_size) and not _changes_over_campaign(
            problem, k, comp_terms[k], added, fit, settings.alpha_constancy, family.name
        ):
            accepted[k] = stats
    if not accepted:
        return None
    return _Candidate(family.name, accepted, sum(s['bic_gain'] for s in accepted.values()))


def _settle_sign_shape(
    problem, k, terms, fit, offered, taken, settings, family: CandidateFamily
) -> list[tuple[str, ...]]:
    """The shape of a sign asymmetry on component k, once the family's first group has passed its
    level there: settled at the leftovers' lack-of-fit level (settings.alpha_lack_of_fit, what
    they would call structure left over), not at the family's Bonferroni level again.

    - A one-sided curvature pair whose one term the points do not resolve keeps the other
      (B660H F_Z, curvature on negative loads: two points beyond -0.8 capacity, x|x| beside x²|x|
      p 0.2, with leverage 0.89 that doubled their leave-one-out residuals), if it still holds.
    - The other components' load-keyed pairs are not offered here (they were, as the
      curvature of every bridge reaching k through the interactions; measured without them:
      B660H curvature on every bridge 9 -> 8/10 right, met 8/10 both ways, while the dead band
      leaking into LMC6522's forces at 2x goes 8 -> 10/10: at this level the other loads'
      pairs fitted part of an effect outside every family, and a tare was then adopted on it).
    - A shape between the family's groups (|x|^2.5, a flexure buckling, between the one-sided
      quadratic and cubic) is fitted by one group with coefficients that depend on the part of
      the curve the points cover; the body's weight shifts a component's loads between
      orientations (LMC6522 F_Y by 14 % of capacity), so that fit changes with the gravity
      direction and the Chow test would reject the effect on a component that has it. The
      family's next best group (the same side's curvature keyed to the bridge output instead of
      the load) is added while it does, up to the family's max_groups, each step significant at
      that level.

    offered: (whitened candidate columns (N_loaded, m), each group's indices into them, the
    groups' term names); taken: indices into the groups, in the order the selection chose them.
    Returns the groups (a pair possibly reduced to one term); unchanged when no step applies.
    """
    groups = offered[2]
    level = settings.alpha_lack_of_fit
    chosen = [tuple(groups[i]) for i in taken]

    def p_without(shape, term) -> float:
        full = problem.fit(k, list(terms) + _flat(shape)).gls
        less = problem.fit(k, list(terms) + [t for t in _flat(shape) if t != term]).gls
        return partial_f(less.rss, full.rss, 1, full.dof)[1]

    simpler = []
    for group in chosen:
        if len(group) == 2:
            p_values = [p_without(chosen, t) for t in group]
            weakest = int(np.argmax(p_values))
            if p_values[weakest] > level:
                group = (group[1 - weakest],)
        simpler.append(group)
    moving = _coefficients_change(problem, k, terms, simpler, fit, settings, 'bidirectional')
    if simpler != chosen and not moving:
        chosen = simpler
    return _completed_while_moving(problem, k, terms, fit, offered, chosen, settings, family)


def _completed_while_moving(
    problem, k, terms, fit, offered, chosen, settings, family: CandidateFamily
) -> list[tuple[str, ...]]:
    """`chosen` (groups of one family on component k) if its coefficients hold over the campaign
    (_changes_over_campaign); else `chosen` with the family's next best groups added, each step
    significant at the leftovers' lack-of-fit level, up to the family's max_groups in all, as
    soon as the coefficients hold; `chosen` unchanged when no such completion exists (the Chow
    test then rejects it). offered: as for _settle_sign_shape.

    A shape between the family's groups is fitted by one group with coefficients that depend
    on the part of the campaign the points cover: a one-sided |x|^2.5 (see _settle_sign_shape);
    a loop on every bridge of a coupled balance, which reaches a component through several
    bridges whose histories differ between the campaign's halves (B660H F_Y, a Masing or a
    re-seating loop on every bridge: its own bridge's loop term alone rejected by the Chow test
    in seeds 3005 and 3007, which a second play completes; 3005 is then named right).
    """
    candidates, columns, groups = offered
    if not _coefficients_change(problem, k, terms, chosen, fit, settings, family.name):
        return list(chosen)
    current = list(chosen)
    while len(current) < family.max_groups:
        present = set(_flat(current))
        rest = [i for i, g in enumerate(groups) if not set(g) & present]
        if not rest:
            break
        step = forward_select(
            problem.fit(k, list(terms) + _flat(current)).gls,
            candidates,
            [columns[i] for i in rest],
            alpha_per_test=settings.alpha_lack_of_fit,
            max_groups=1,
        )
        if not step.steps:
            break
        current.append(tuple(groups[rest[step.groups[0]]]))
        if not _coefficients_change(problem, k, terms, current, fit, settings, family.name):
            return current
    return list(chosen)


def _completed_at_lack_of_fit(
    problem, k, terms, offered, chosen, settings, max_groups: int
) -> list[tuple[str, ...]]:
    """`chosen` (the loop groups that passed the family's level on component k) with the
    family's next best groups added while each is significant at the leftovers' lack-of-fit
    level (settings.alpha_lack_of_fit, Bonferroni over the groups left), up to max_groups: once
    a loop is established its shape is settled at the level at which the leftovers would call
    what remains structure, as _settle_sign_shape does for a sign asymmetry. offered: as there.

    A loop the family does not contain is a blend of its plays (an Iwan joint is a sum of plays
    of every width): B660H, a Bouc-Wen loop on every bridge, seed 3009, M_Z's second play is
    taken here, cross-validated σ 1.15x -> 1.09x the clean floor.
    """
    candidates, columns, groups = offered
    current = list(chosen)
    while len(current) < max_groups:
        present = set(_flat(current))
        rest = [i for i, g in enumerate(groups) if not set(g) & present]
        if not rest:
            break
        step = forward_select(
            problem.fit(k, list(terms) + _flat(current)).gls,
            candidates,
            [columns[i] for i in rest],
            alpha_per_test=settings.alpha_lack_of_fit / len(rest),
            max_groups=1,
        )
        if not step.steps:
            break
        current.append(tuple(groups[rest[step.groups[0]]]))
    return current


def _flat(shape) -> list[str]:
    """The term names of a list of groups, in order."""
    return [t for g in shape for t in g]


def _coefficients_change(problem, k, terms, shape, fit, settings, family: str) -> bool:
    """Do the groups `shape` added to component k's terms fit with coefficients that change over
    the campaign (_changes_over_campaign at settings.alpha_constancy)?
    """
    return _changes_over_campaign(
        problem, k, terms, _flat(shape), fit, settings.alpha_constancy, family
    )


def _level_shares(
    family: CandidateFamily,
    groups: Sequence[tuple[str, ...]],
    candidates: np.ndarray,
    columns: Sequence[tuple[int, ...]],
    problem: _Problem,
    k: int,
    settings: DiagnosisSettings,
) -> np.ndarray:
    """(groups,) the share of the family's level each group offered to component k is tested at
    (weighted Bonferroni; they sum to 1). Flat except for zero_drift and temperature, see
    DiagnosisSettings.drift_spectrum_exponent and temperature_level_shares. candidates: the
    groups' whitened columns (N, m), columns: each group's indices into them.
    """
    weights = np.ones(len(groups))
    if family.name == 'zero_drift' and family.frequencies_hz:
        frequency = dict(zip(family.groups, family.frequencies_hz))
        f = np.array([frequency[tuple(g)] for g in groups])
        energy = np.array([np.sum(candidates[:, list(c)] ** 2) for c in columns])
        weights = energy * f**-settings.drift_spectrum_exponent
    elif family.name == 'temperature':
        own = problem.outputs_names[k]
        tiers = np.array([_temperature_tier(g[0], own) for g in groups])
        shares = np.asarray(settings.temperature_level_shares, dtype=float)
        present = [t for t in range(len(shares)) if np.any(tiers == t)]
        total = sum(shares[t] for t in present)
        weights = np.array([shares[t] / total / np.sum(tiers == t) for t in tiers])
    total = float(np.sum(weights))
    if not np.isfinite(total) or total <= 0:
        return np.full(len(groups), 1.0 / len(groups))
    return weights / total


def _temperature_tier(term: str, own_output: str) -> int:
    """0: first order in dT on the component's own bridge (or none), 1: second order there,
    2: another bridge's output.
    """
    factors = parse_terms([term])[0].factors
    outputs = {f.variable for f in factors if f.variable != 'dT'}
    power = sum(f.power for f in factors if f.variable == 'dT')
    if outputs - {own_output}:
        return 2
    return 0 if power <= 1 else 1


def _changes_over_campaign(problem, k, terms, added, fit, alpha, family) -> bool:
    """Chow tests: do the added terms' coefficients differ between the first and the second half of
    the campaign (static families), or between the body's orientations with gravity on the + and
    the - side of Y+Z (every family but tare)? A physical effect of the family keeps its
    coefficients; something it only resembles (a load-dependent term that drifts, one that flips
    with the gravity direction, a temperature that lags) fits with coefficients that move.
    """
    splits = []
    if family in STATIC_FAMILIES:
        splits.append((problem.times > np.median(problem.times)).astype(float))
    if family != 'tare' and problem.gravity is not None:
        side = (problem.gravity[:, 1] + problem.gravity[:, 2] > 0).astype(float)
        if 0 < side.sum() < len(side):
            splits.append(side)
    base = problem.white_columns(list(terms) + list(added))
    current = fit_columns(base, problem.loads_white[:, k])
    for split in splits:
        extra = problem.whiten(problem.columns(list(added)) * split[:, None])
        trial = fit_columns(np.hstack([base, extra]), problem.loads_white[:, k])
        q = trial.rank - current.rank
        if q <= 0 or trial.dof <= 0:
            continue
        _, p_value = partial_f(current.rss, trial.rss, q, trial.dof)
        if p_value * len(splits) < alpha:
            return True
    return False


def _examine_excitation(family, state: SearchState):
    """One gain g(t) common to every bridge: a joint forward selection over the six components
    (whitened residuals scaled by their σ, stacked), each basis function one shared parameter.
    """
    fits, comp_terms, problem = state.fits, state.comp_terms, state.problem
    capacity, settings = state.capacity, state.settings
    n_components = len(fits)
    groups = [g for g in family.groups if not any(set(g) & set(terms) for terms in comp_terms)]
    if not groups:
        return None
    sigmas = np.sqrt([f.gls.variance for f in fits])
    n_white = fits[0].gls.points
    residual = np.concatenate([f.gls.residuals / s for f, s in zip(fits, sigmas)])
    blocks = [f.gls.basis for f in fits]
    basis = np.zeros((n_white * n_components, sum(b.shape[1] for b in blocks)))
    column = 0
    for k, b in enumerate(blocks):
        basis[k * n_white : (k + 1) * n_white, column : column + b.shape[1]] = b
        column += b.shape[1]
    stacked = LeastSquares.of_projection(basis, residual)
    columns = np.column_stack(
        [
            np.concatenate(
                [problem.white_columns([g[k]])[:, 0] / sigmas[k] for k in range(n_components)]
            )
            for g in groups
        ]
    )
    selection = forward_select(
        stacked,
        columns,
        [(i,) for i in range(len(groups))],
        alpha_per_test=settings.alpha / len(groups) / n_components,
        max_groups=family.max_groups,
    )
    if not selection.steps:
        return None
    chosen = [groups[i] for i in selection.groups]
    q = len(chosen)
    f_joint, p_joint = partial_f(
        selection.rss_before, selection.steps[-1].rss_after, q, selection.dof_before - q
    )
    # the score with the gain shared, as the effect is: Σ_k n ln(RSS_k before / after) - q ln n
    picked = columns[:, list(selection.groups)]
    picked = picked - basis @ (basis.T @ picked)
    coefficients = minimum_norm_solve(picked, residual).solution
    shared = (residual - picked @ coefficients).reshape(n_components, n_white)
    before = residual.reshape(n_components, n_white)
    score = float(
        sum(n_white * np.log(np.sum(b**2) / np.sum(a**2)) for b, a in zip(before, shared))
        - q * np.log(n_white)
    )
    accepted = {}
    for k, fit in enumerate(fits):
        added = [g[k] for g in chosen]
        stats = _component_statistics(fit, problem.fit(k, comp_terms[k] + added), capacity[k], 1)
        stats.update(
            added=tuple(added),
            groups=tuple((t,) for t in added),
            f=f_joint,
            p=min(1.0, p_joint * len(groups) * n_components),
            label='a gain common to all bridges (' + family.label(chosen) + ')',
        )
        if _passes(stats, settings):
            accepted[k] = stats
    # a gain common to all bridges shows in more than one component; one alone is that bridge's own
    # effect
    if len(accepted) < 2:
        return None
    return _Candidate(family.name, accepted, score)
