"""Residual diagnosis: which physical effect does the base model of TM-663 lack?

After the base fit (cubic, §2.3) of the corrected data (§5(4) zero points, §6-7 tare), the
residuals of every component are examined against each candidate family of shapes (candidates.py,
tare_refit.py): temperature, zero_drift, hysteresis, bidirectional, cross_terms, tare, creep and
excitation. Per round, for every family and component:

1. forward selection of the family's terms, each step a partial F-test at a level Bonferroni-
   corrected *within the family* (α / (its candidate groups × components)): one test per family,
   not one search-wide level, so a specific effect is not drowned by the size of the generic
   families. The tests run on the loaded points whitened against the noise the zero points share
   with their block (generalised least squares, statistics.ZeroPointWhitening). Excitation (one
   gain common to all bridges) is one joint selection over the six components stacked;
2. the component counts only if the terms remove at least `min_effect_pct_fs` (RMS, % FS), the
   cross-validated σ (PRESS, e_i / (1 - h_ii), of the eq. (19) fit) improves, and -- for the static
   families (hysteresis, bidirectional, cross terms, creep) -- their coefficients do not change
   between the campaign's halves (a Chow test: something the family only resembles would);
3. families are ranked by the gain in BIC, Σ_k [n ln(RSS_before/RSS_after) - q_k ln n] (whitened,
   n loaded points); a generic family (cross_terms, zero_drift) winning by less than `equal_score`
   yields to the specific one. Hysteresis and bidirectional keep only the components their contrast
   explains (loop_or_sign.py: the loading and unloading branches at equal load differ for a loop,
   not for a sensitivity keyed to the load's sign). A runner-up about as good as the winner that
   no longer passes once the winner is in explained the same residual: a warning ("cannot
   separate"), not a second name.

The best family is added (its terms only for its components), everything refitted, and the search
repeats until no family passes. Then lack_of_fit.py tests what remains against the repeatability of
the points (lack of fit), and for a component's own load shape changing with time or with the
gravity vector (directed tests), and reports structure no family explains as `unexplained`,
dropping the families that fitted only part of it. The adopted fit keeps every term; the live model
drops the nuisance ones (time basis, creep, excitation) and the terms the live calibrator cannot
evaluate (loops keyed to the turning point or a bridge's play, the sign of the fitted load): it
needs only outputs, dT and the load directions.
"""

from __future__ import annotations

from typing import cast

import numpy as np

from ..accuracy.sigma import sigma_pct_fs
from ..config import BalanceConfig
from ..model.balance_model import BalanceModel
from ..model.terms import parse_terms
from ..reduction import Reduction
from .candidates import (
    GENERIC_FAMILIES,
)
from .effect_found import _effect_found
from .families import _examine_excitation, _examine_family
from .lack_of_fit import examine_lack_of_fit
from .loop_or_sign import beside_its_partner, direction_pairs
from .offered import families_offered
from .result import Diagnosis, EffectFound
from .retare import _complete_curvature_pairs, _examine_tare, _retare_passes
from .search import (
    _cross_terms_only_where_lacking,
    _fitted_well,
    _inseparable_warning,
    _told_apart_by_direction,
)
from .search_state import _Candidate, _Problem, SearchState
from .settings import DiagnosisSettings
from .statistics import ZeroPointWhitening
from .tare_refit import BodyRefit

__all__ = ['Diagnosis', 'DiagnosisSettings', 'EffectFound', 'diagnose']


def diagnose(
    reduction: Reduction,
    config: BalanceConfig,
    *,
    base_model: str = 'cubic',
    temperature_c=None,
    times_s=None,
    settings: DiagnosisSettings = DiagnosisSettings(),
    point_variance_mv2=None,
    point_samples=None,
) -> Diagnosis:
    """Examine the residuals of the base fit and add the effects they show.

    point_variance_mv2 (P, 6), point_samples (P,): the variance of each point's mean output from
    its own samples and their number, when the samples are at hand (repeatability, lack_of_fit.py);
    without them the repeatability comes from consecutive zero points alone.

    reduction: the corrected data (zero points and tare done); temperature_c, times_s: per point
    (default: those of reduction.points; temperature all-NaN -> the temperature effect is skipped).
    """
    points = reduction.points
    components, outputs_names = tuple(config.components), tuple(config.bridge_outputs)
    capacity = np.asarray(config.capacity, dtype=float)
    times = np.asarray(points.times_s if times_s is None else times_s, dtype=float)
    temps = np.asarray(
        points.temperature_c if temperature_c is None else temperature_c, dtype=float
    )
    corrected = reduction.corrected
    offered = families_offered(reduction, config, base_model, times, temps, settings)
    base_terms, variables, families = offered.base_terms, offered.variables, offered.families
    raw_direction, tare_available = offered.raw_direction, offered.tare_available
    skipped, reference_temperature = offered.skipped, offered.reference_temperature

    whitening = ZeroPointWhitening.for_points(
        points.times_s, points.is_zero_point, points.orientation
    )
    problem = _Problem(
        outputs_names, corrected, variables, whitening, components, times, points.gravity
    )
    comp_terms = [list(base_terms) for _ in components]
    base_fits = [problem.fit(k, comp_terms[k]) for k in range(len(components))]
    state = SearchState(
        problem,
        list(base_fits),
        comp_terms,
        base_fits,
        base_terms,
        settings,
        capacity,
        variables,
        points,
        raw_direction,
        times,
        temps,
        point_variance_mv2,
        point_samples,
    )
    base_coefficients = np.array([f.ols.coefficients for f in base_fits])
    body, body_source = reduction.body, reduction.body_source

    # the schedule's own pairs (contrasts.py): equal load reached rising and falling
    pairs = direction_pairs(corrected, points.orientation, raw_direction, capacity)
    effects: list[dict] = []
    adopted_families: set[str] = set()
    fitted_well = _fitted_well(state)
    warnings: list[str] = []
    close_runners: list = []  # (winner, runner-up) of the last round, scores about equal
    for _round in range(settings.max_rounds):
        candidates: list[_Candidate] = []
        for family in families:
            if family.name in adopted_families:
                continue
            if family.name == 'excitation':
                candidate = _examine_excitation(family, state)
            else:
                candidate = _examine_family(
                    family,
                    state,
                    1,
                    beside_its_partner(family.name, effects, state.fits, fitted_well),
                )
            if candidate:
                candidates.append(candidate)
        if tare_available and 'tare' not in adopted_families:
            candidate = _examine_tare(state, body, 1)
            if candidate:
                candidates.append(candidate)
        candidates = _told_apart_by_direction(candidates, state.fits, pairs)
        candidates = _cross_terms_only_where_lacking(candidates, state.fits, effects, fitted_well)
        present = {c.family for c in candidates}
        for won, runner in close_runners:
            if runner.family not in present:
                warnings.append(_inseparable_warning(won, runner, components))
        if not candidates:
            break
        winner = max(candidates, key=lambda c: c.score)
        # a generic family (a time basis, any monomial) that wins only narrowly over a specific one
        # yields to it: the specific effect explains about as much with its physics
        specific = [
            c
            for c in candidates
            if c.family not in GENERIC_FAMILIES and c.score >= settings.equal_score * winner.score
        ]
        if winner.family in GENERIC_FAMILIES and specific:
            winner = max(specific, key=lambda c: c.score)
        close_runners = [
            (winner, c)
            for c in candidates
            if c is not winner
            and c.family != 'tare'
            and winner.family != 'tare'
            and c.score >= settings.equal_score * winner.score
            and set(c.components) & set(winner.components)
        ]
        adopted_families.add(winner.family)
        before = {k: state.fits[k] for k in winner.components}
        if winner.family == 'tare':
            refit = cast(BodyRefit, winner.body_refit)  # a tare candidate carries both
            problem.set_corrected(refit.corrected)
            body, body_source = refit.body, 'fitted'
            state.fits = list(cast(list, winner.components_fits))
        else:
            for k, stats in winner.components.items():
                comp_terms[k] = comp_terms[k] + list(stats['added'])
                state.fits[k] = stats['fit']
        effects.append({'candidate': winner, 'before': before})

    # --- what is left: lack of fit against the repeatability, unexplained structure ------------
    # judged with the tare re-read through the adopted model (_retare); where the leftovers drop
    # an effect, the reduction's tare is read again through the model without it (the leftovers'
    # numbers stay those of the first reading)
    reduced = problem.corrected
    state.fits, tare_reread = _retare_passes(state, effects)
    if _complete_curvature_pairs(state, effects):
        state.fits, again = _retare_passes(state, effects)
        tare_reread |= again
    leftovers = examine_lack_of_fit(state, effects)
    for k, dropped in leftovers.dropped.items():
        comp_terms[k] = [t for t in comp_terms[k] if t not in dropped]
        for entry in effects:
            entry['candidate'].components.pop(k, None)
    effects = [e for e in effects if e['candidate'].components]
    warnings += leftovers.warnings
    if leftovers.dropped:
        problem.set_corrected(reduced)
        state.fits = [problem.fit(k, comp_terms[k]) for k in range(len(components))]
        state.fits, tare_reread = _retare_passes(state, effects)
    fits = state.fits
    named = list(fits)
    for k, dropped in leftovers.dropped.items():
        named[k] = problem.fit(k, comp_terms[k] + sorted(dropped))

    # --- assemble -----------------------------------------------------------------------------
    all_terms = list(base_terms)
    for terms in comp_terms:
        all_terms += [t for t in terms if t not in all_terms]
    coefficients = np.zeros((len(components), len(all_terms)))
    for k, terms in enumerate(comp_terms):
        coefficients[k, [all_terms.index(t) for t in terms]] = fits[k].ols.coefficients
    label = '+'.join([base_model] + [e['candidate'].family for e in effects])
    adopted = BalanceModel(label, parse_terms(all_terms), coefficients, components, outputs_names)
    base = BalanceModel(
        base_model, parse_terms(base_terms), base_coefficients, components, outputs_names
    )
    live_ok = set(outputs_names) | {'dT'} | {f'dir_{c}' for c in components}
    live_terms = [t.name for t in adopted.terms if set(t.variables) <= live_ok]
    live = adopted.restricted_to(live_terms, name=label + ' (live)')
    used = set(adopted.extra_variables)
    extra_values = {name: values for name, values in variables.items() if name in used}

    found = tuple(
        _effect_found(e, fits, comp_terms, components, problem, points, times, set(live_terms))
        for e in effects
    )

    def sigma_row(fit_list, press=False):
        return {
            c: sigma_pct_fs(f.ols.press_residuals if press else f.ols.residuals, capacity[k])
            for k, (c, f) in enumerate(zip(components, fit_list))
        }

    return Diagnosis(
        balance=config.name,
        base_model=base_model,
        components=components,
        capacity=capacity,
        effects=found,
        sigma_pct_fs={'before': sigma_row(base_fits), 'after': sigma_row(fits)},
        sigma_pct_fs_crossval={
            'before': sigma_row(base_fits, True),
            'after': sigma_row(fits, True),
        },
        base_fit=base,
        adopted=adopted,
        live=live,
        live_variables=live.extra_variables,
        extra_variables=extra_values,
        reference_temperature_c=reference_temperature,
        calibration_body=body,
        body_source=body_source,
        corrected=problem.corrected,
        point_labels=np.asarray(points.label),
        times_s=times,
        orientation=np.asarray(points.orientation),
        load_direction=raw_direction,
        residuals_before=np.column_stack([f.ols.residuals for f in base_fits]),
        residuals_after=np.column_stack([f.ols.residuals for f in fits]),
        press_residuals_before=np.column_stack([f.ols.press_residuals for f in base_fits]),
        press_residuals_after=np.column_stack([f.ols.press_residuals for f in fits]),
        skipped=skipped,
        unexplained=leftovers.unexplained,
        repeatability_pct_fs=leftovers.repeatability_pct_fs,
        warnings=tuple(dict.fromkeys(warnings)),
        lack_of_fit=leftovers,
        tare_reread=tare_reread,
        residuals_named=np.column_stack([f.ols.residuals for f in named]),
        press_residuals_named=np.column_stack([f.ols.press_residuals for f in named]),
    )
