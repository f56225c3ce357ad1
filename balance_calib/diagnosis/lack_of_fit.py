"""What the adopted model leaves: repeatability, lack of fit, "unexplained" structure, warnings.

The yardstick is the repeatability of the points themselves: consecutive zero points in the same
orientation (TM-663 §5(4) brackets every block with them, and the end of one block is usually the
start of the next) differ only by the noise of two points and the drift of one point spacing, so
var(ΔL) = 2 s², ΔL the output difference through the linear part of the fit. A component whose
whitened residual variance is beyond s² (F-test with the residual's and the ν pairs' degrees of
freedom, level alpha_lack_of_fit / 6) has structure left over.

Beside that omnibus test, directed tests (slow_structure_bases) look for the component's own load
shape (x, x², x|x|) changing with time, with the gravity vector, or with both: structure a
calibration that holds throughout the campaign and in every orientation cannot have, concentrated
in three to six columns where the omnibus test spreads it over hundreds of degrees of freedom
(partial F-tests on the whitened fit, level alpha_slow_structure per campaign, Bonferroni over the
components and bases, and it must remove at least min_effect_pct_fs).

Such structure is reported as `unexplained`, with what it follows most strongly (`tracks`). When
the effects found on that component explain less than `min_explained` of its excess variance
(base-model variance minus s²; for a directed finding, of the structure along its basis together
with what they removed), or fit it with coefficients that differ between the first and the
second half of the campaign (a Chow test), none of them is adopted there: they fit part of
something else, and adopting them would put the wrong physics into the live model.

Caveat: the zero points do not see scatter of the loading hardware (weights, pans, alignment), so
on real data the loaded points can be less repeatable than s says; the zero-point scatter is a
lower bound of the repeatability, and `unexplained` then also flags that.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np
import scipy.stats

from ..accuracy.sigma import sigma_pct_fs
from ..fit.svd import minimum_norm_solve
from .candidates import STATIC_FAMILIES
from .search_state import SearchState
from .statistics import fit_columns, partial_f

# A component whose repeatability is this many times the median of the others is warned about.
REPEATABILITY_WARNING_RATIO = 4.0  # LMC6522's own F_X (Table 17) is ~3x its other components
# A calibration body rolled by more than this (degrees) from the declared gravity direction.
ROLL_WARNING_DEG = 0.4  # the fit-based estimate scatters ±0.2° on clean simulated campaigns


@dataclass(frozen=True)
class Unexplained:
    components: tuple[str, ...]
    evidence: str
    tracks: str
    sigma_pct_fs: Mapping[str, float]
    ratio: float  # residual variance / repeatability²
    p_value: float
    correlation: float
    partly_fitted_by: tuple[str, ...] = ()  # families that fitted part of it (not adopted there)
    tracks_values: np.ndarray | None = None  # (N,) the variable it follows (plot)
    residual: np.ndarray | None = None  # (N,) leftover residual, N or N·m

    def to_report(self) -> dict:
        return {
            'components': list(self.components),
            'evidence': self.evidence,
            'tracks': self.tracks,
            'sigma_pct_fs': {c: round(float(v), 4) for c, v in self.sigma_pct_fs.items()},
        }


@dataclass(frozen=True)
class LackOfFit:
    repeatability_pct_fs: Mapping[str, float]
    pairs: int  # ν: pairs of consecutive zero points
    lack_of_fit_ratio: Mapping[str, float]
    lack_of_fit_p: Mapping[str, float]
    unexplained: tuple[Unexplained, ...]
    warnings: list[str] = field(default_factory=list)
    # component index -> terms not adopted
    dropped: Mapping[int, set] = field(default_factory=dict)
    roll_deg: float | None = None


def linear_part(fits, comp_terms, outputs_names) -> np.ndarray:
    """(6, 6) dL_k/dV_i from the linear terms of each component's fit."""
    return np.array(
        [
            [fit.ols.coefficients[terms.index(v)] if v in terms else 0.0 for v in outputs_names]
            for fit, terms in zip(fits, comp_terms)
        ]
    )


def zero_point_pairs(points) -> np.ndarray:
    """(ν, 6) output differences of time-consecutive zero points in the same orientation."""
    order = np.argsort(np.asarray(points.times_s, float), kind='stable')
    zero = np.asarray(points.is_zero_point)[order]
    orientation = np.asarray(points.orientation)[order]
    outputs = np.asarray(points.outputs_mv, float)[order]
    both = zero[1:] & zero[:-1] & (orientation[1:] == orientation[:-1])
    return (outputs[1:] - outputs[:-1])[both]


def _output_model_loads(fits, comp_terms, outputs_names, outputs) -> np.ndarray:
    """(M, 6) loads of the fitted model's output-only terms (no constant) at outputs (M, 6)."""
    from ..model.terms import as_variables, design_matrix, parse_terms

    outputs = np.atleast_2d(outputs)
    loads = np.zeros((len(outputs), len(fits)))
    for k, (fit, terms) in enumerate(zip(fits, comp_terms)):
        keep = [
            i
            for i, t in enumerate(parse_terms(terms))
            if t.variables and set(t.variables) <= set(outputs_names)
        ]
        design = design_matrix(
            parse_terms([terms[i] for i in keep]),
            as_variables(outputs_names, outputs),
            len(outputs),
        )
        loads[:, k] = design @ fit.ols.coefficients[keep]
    return loads


def body_roll_deg(points, fits, comp_terms, outputs_names) -> float | None:
    """Mean roll (about X, degrees) of the body-weight force from opposite zero points relative to
    the declared gravity direction; None without opposite pairs in the Y-Z plane.

    V(±g) = e + V_body(±g); the electrical zero e is taken as the mean of (V(g) + V(-g)) / 2 over
    the pairs, and the fitted model (its nonlinear terms included: the linear part alone is off by
    0.2-0.4° at the body's weight) gives the force at each.
    """
    zero = np.asarray(points.is_zero_point)
    means: dict[tuple[float, ...], list[np.ndarray]] = {}
    for g, v in zip(np.asarray(points.gravity)[zero], np.asarray(points.outputs_mv)[zero]):
        means.setdefault(tuple(np.round(g, 6)), []).append(v)
    mean_of = {key: np.mean(v, axis=0) for key, v in means.items()}
    pairs = [
        (np.array(key), mean_of[key], mean_of[tuple(np.round(-np.array(key), 6) + 0.0)])
        for key in mean_of
        if tuple(np.round(-np.array(key), 6) + 0.0) in mean_of
        and key > tuple(np.round(-np.array(key), 6) + 0.0)
    ]
    if not pairs:
        return None
    electrical = np.mean([(a + b) / 2.0 for _, a, b in pairs], axis=0)
    angles = []
    for g, plus, minus in pairs:
        loads = _output_model_loads(
            fits, comp_terms, outputs_names, np.vstack([plus, minus]) - electrical
        )
        force = (loads[0] - loads[1])[:3] / 2.0
        if np.hypot(g[1], g[2]) < 0.5 or np.hypot(force[1], force[2]) <= 0:
            continue
        angles.append(
            np.degrees(
                np.arctan2(g[1] * force[2] - g[2] * force[1], g[1] * force[1] + g[2] * force[2])
            )
        )
    return float(np.mean(angles)) if angles else None


def _trackers(points, variables, direction, times, temps, loads, components):
    loaded = ~np.asarray(points.is_zero_point)
    t = (times - times.mean()) / max(np.ptp(times), 1e-9)
    trackers = {'time': np.column_stack([t, t**2])}
    if 'dT' in variables:
        trackers['temperature'] = np.column_stack([variables['dT'], variables['dT'] ** 2])
    for k, c in enumerate(components):
        x = loads[:, k] / max(np.max(np.abs(loads[:, k])), 1e-12)
        trackers[f'load {c}'] = np.column_stack([x, x**2, np.abs(x)])
    d = np.asarray(direction, float)
    scaled = loads / np.maximum(np.max(np.abs(loads), axis=0), 1e-12)
    trackers['load history'] = np.hstack([d, d * np.abs(scaled)])
    trackers['gravity direction'] = np.asarray(points.gravity, float)
    trackers['point order'] = np.column_stack([np.cos(np.pi * np.arange(len(t)))])
    return {name: values[loaded] for name, values in trackers.items()}, loaded


def _best_tracker(residual, trackers, alpha=0.01):
    """(name, multiple r, p) of the tracker explaining most of the residual; 'nothing found' if
    none passes.
    """
    n = len(residual)
    best = ('nothing found', 0.0, 1.0)
    total = float(np.sum((residual - residual.mean()) ** 2))
    if total <= 0:
        return best
    for name, columns in trackers.items():
        design = np.column_stack([np.ones(n), columns])
        coefficients = minimum_norm_solve(design, residual).solution
        rss = float(np.sum((residual - design @ coefficients) ** 2))
        q = np.linalg.matrix_rank(design) - 1
        if q <= 0 or n - q - 1 <= 0:
            continue
        r2 = max(1.0 - rss / total, 0.0)
        f = (total - rss) / q / max(rss / (n - q - 1), 1e-300)
        p = float(scipy.stats.f.sf(f, q, n - q - 1)) * len(trackers)
        if p < alpha and np.sqrt(r2) > best[1]:
            best = (name, float(np.sqrt(r2)), p)
    return best


def slow_structure_bases(times, gravity, loads_k) -> dict[str, np.ndarray]:
    """The directed leftover tests' bases for one component: its own load shape -- gain x, even
    curvature x², odd curvature x|x| (x = applied load / its largest magnitude) -- changing with
    the campaign's two slow covariates, time and the gravity vector in balance axes (each component
    that varies), and with their product (main effects and interaction). A calibration that is the
    same throughout the campaign and in every orientation leaves none of them in the residual; the
    omnibus lack-of-fit test spreads such structure over all its degrees of freedom, these
    concentrate it in three. Built from the applied loads, which carry no noise (a test column,
    never adopted).
    """
    t = np.asarray(times, float)
    t = (t - t.mean()) / max(float(np.ptp(t)), 1e-9)
    x = np.asarray(loads_k, float) / max(float(np.max(np.abs(loads_k))), 1e-12)
    shape = np.column_stack([x, x**2, x * np.abs(x)])
    bases = {'time': t[:, None] * shape}
    g = np.asarray(gravity, float)
    varying = [g[:, i] for i in range(g.shape[1]) if np.ptp(g[:, i]) > 1e-6]
    if varying:  # the body's weight loads the mounting linearly in the gravity vector
        by_gravity = np.hstack([gi[:, None] * shape for gi in varying])
        bases['gravity direction'] = by_gravity
        bases['time × gravity direction'] = t[:, None] * by_gravity
    return bases


def _directed_reduction(problem, k, terms, basis) -> tuple[float, float, int, int]:
    """(rss before, rss after, columns added, dof after) of the whitened fit of component k with
    the basis added.
    """
    design = problem.white_columns(list(terms))
    current = fit_columns(design, problem.loads_white[:, k])
    trial = fit_columns(np.hstack([design, problem.whiten(basis)]), problem.loads_white[:, k])
    return current.rss, trial.rss, trial.rank - current.rank, trial.dof


def directed_lack_of_fit(problem, k, terms, base_terms, bases, alpha, n_tests):
    """The most significant slow structure left on component k: (name, p adjusted, explained) or
    None when none passes alpha. explained: the share the adopted terms beyond the base model took
    of all the structure the base fit leaves in their span and the basis's together (whitened RSS),
    (RSS_base - RSS_adopted) / (RSS_base - RSS_adopted+basis) -- the omnibus rule's "fraction of
    the excess explained" (examine_lack_of_fit), with the excess measured along the basis.
    """
    best = None
    for name, basis in bases.items():
        before, after, q, dof = _directed_reduction(problem, k, terms, basis)
        if q <= 0 or dof <= 0:
            continue
        _, p = partial_f(before, after, q, dof)
        p = min(1.0, p * n_tests)
        if p < alpha and (best is None or p < best[1]):
            base_rss = fit_columns(
                problem.white_columns(list(base_terms)), problem.loads_white[:, k]
            ).rss
            structure = base_rss - after
            explained = (base_rss - before) / structure if structure > 0 else 0.0
            best = (name, p, explained)
    return best


def within_point_variance(linear, point_variance_mv2, point_samples, loaded):
    """(6,) variance of a point mean in load units from the points' own sample scatter, and its
    dof.

    point_variance_mv2 (P, 6): variance of each point's mean output (sample variance / n);
    bridges independent: var L_k = Σ_i C_ki² var V_i.
    """
    variance = np.asarray(point_variance_mv2, float)[loaded]
    samples = np.asarray(point_samples, float)[loaded]
    ok = np.all(np.isfinite(variance), axis=1) & (samples >= 2)
    if ok.sum() < 3:
        return None, 0
    return np.mean(variance[ok] @ (linear**2).T, axis=0), int(np.sum(samples[ok] - 1))


def repeatability_variance(
    points, linear, pairs, components, point_variance_mv2=None, point_samples=None
) -> tuple[np.ndarray, np.ndarray, dict[str, str], list[str]]:
    """(6,) s², the variance of one point's load from its repeatability (module docstring), its
    degrees of freedom ν and where it came from per component, and warnings: consecutive zero
    points through the fit's linear part, or the points' own samples where they are at hand and
    the zero points do not repeat significantly worse. pairs: zero_point_pairs (at least one).
    """
    n_components = len(components)
    noted: list[str] = []
    delta_loads = pairs @ linear.T
    s2 = np.mean(delta_loads**2, axis=0) / 2.0
    nu = np.full(n_components, len(pairs), dtype=float)
    source = {c: f'{len(pairs)} pairs of consecutive zero points' for c in components}
    if point_variance_mv2 is not None and point_samples is not None:
        # the points' own samples: many more degrees of freedom, but blind to noise slower than a
        # point; kept unless the zero points repeat significantly worse (then they are the
        # yardstick)
        s2_within, nu_within = within_point_variance(
            linear, point_variance_mv2, point_samples, ~np.asarray(points.is_zero_point)
        )
        if s2_within is not None:
            for k, c in enumerate(components):
                p_worse = scipy.stats.f.sf(s2[k] / s2_within[k], len(pairs), nu_within)
                if p_worse < 0.001 / n_components:
                    noted.append(
                        f"{c}: consecutive zero points repeat worse than the points' own samples "
                        f'({np.sqrt(s2[k] / s2_within[k]):.1f}x): noise slower than a point, or '
                        'an effect that shows at zero load too'
                    )
                s2[k], nu[k] = s2_within[k], nu_within
                source[c] = f"the scatter of the points' own samples ({nu_within} dof)"
    return s2, nu, source, noted


def lack_of_fit(gls, s2: float, nu: float) -> tuple[float, float]:
    """The residual variance of a whitened fit (fit/least_squares.LeastSquares) against the
    repeatability s² with ν degrees of freedom: (ratio, p of the F test).
    """
    variance = gls.rss / gls.dof
    ratio = variance / s2 if s2 > 0 else float('inf')
    return float(ratio), float(scipy.stats.f.sf(ratio, gls.dof, nu))


def lacks_fit(gls, s2: float, nu: float, capacity: float, settings, n_components: int) -> bool:
    """Structure left over on one component: lack of fit at alpha_lack_of_fit / n_components and
    an excess over the repeatability of at least min_effect_pct_fs (% FS).
    """
    _, p = lack_of_fit(gls, s2, nu)
    excess = np.sqrt(max(gls.rss / gls.dof - s2, 0.0)) / capacity * 100.0
    return p < settings.alpha_lack_of_fit / n_components and excess >= settings.min_effect_pct_fs


def _unstable(problem, k, terms, fit, found, late, alpha) -> list[tuple[str, float]]:
    """Families found on component k whose coefficients differ between the first and second half of
    the campaign (a Chow test on their terms x the second-half indicator): a physical effect of
    that family keeps its coefficients; something else that the family only resembles does not.
    """
    out = []
    for entry in found:
        if entry['candidate'].family not in STATIC_FAMILIES:
            continue
        added = list(entry['candidate'].components[k]['added'])
        if not added:
            continue
        extra = problem.whiten(problem.columns(added) * late[:, None])
        trial = fit_columns(
            np.hstack([problem.white_columns(list(terms)), extra]), problem.loads_white[:, k]
        )
        q = trial.rank - fit.gls.rank
        if q <= 0 or trial.dof <= 0:
            continue
        f = (fit.gls.rss - trial.rss) / q / max(trial.rss / trial.dof, 1e-300)
        p = float(scipy.stats.f.sf(f, q, trial.dof)) * len(found)
        if p < alpha:
            out.append((entry['candidate'].family, p))
    return out


def examine_lack_of_fit(state: SearchState, effects) -> LackOfFit:
    """What is left after the search (state: its fits, terms and data; effects: the adopted
    candidates): repeatability, lack of fit, unexplained structure, warnings.
    """
    points, problem, fits, comp_terms = state.points, state.problem, state.fits, state.comp_terms
    base_fits, base_terms, settings = state.base_fits, state.base_terms, state.settings
    components, outputs_names, capacity = state.components, state.outputs_names, state.capacity
    variables, direction, times, temps = state.variables, state.direction, state.times, state.temps
    point_variance_mv2, point_samples = state.point_variance_mv2, state.point_samples
    n_components = len(components)
    linear = linear_part(fits, comp_terms, outputs_names)
    pairs = zero_point_pairs(points)
    warnings: list[str] = []
    roll = body_roll_deg(points, fits, comp_terms, outputs_names)
    if roll is not None and abs(roll) > ROLL_WARNING_DEG:
        warnings.append(
            f'the calibration body sits rolled by {roll:.2f}° about X from the declared gravity '
            "direction (body-weight force from opposite zero points): check the body's "
            "mounting and "
            f'the declared orientations'
        )
    nan = {c: float('nan') for c in components}
    if len(pairs) < 3:
        warnings.append(
            f'only {len(pairs)} pair(s) of consecutive zero points in one orientation: the '
            'repeatability is unknown and the residuals were not tested for lack of fit'
        )
        return LackOfFit(nan, len(pairs), nan, nan, (), warnings, {}, roll)
    s2, nu, source, noted = repeatability_variance(
        points, linear, pairs, components, point_variance_mv2, point_samples
    )
    warnings += noted
    values = np.sqrt(s2) / capacity * 100.0
    for k, c in enumerate(components):
        others = np.median(np.delete(values, k))
        if others > 0 and values[k] > REPEATABILITY_WARNING_RATIO * others:
            warnings.append(
                f'{c} repeats far worse than the other components ({values[k]:.3f} vs a median of '
                f'{others:.3f} % FS): check that bridge, its wiring '
                'and amplifier channel'
            )

    repeatability = {
        c: float(np.sqrt(s2[k]) / capacity[k] * 100.0) for k, c in enumerate(components)
    }
    loads = np.asarray(problem.corrected.loads, float)
    trackers, loaded = _trackers(points, variables, direction, times, temps, loads, components)
    per_component = {
        k: [
            e
            for e in effects
            if k in e['candidate'].components and e['candidate'].family != 'tare'
        ]
        for k in range(n_components)
    }
    ratios, p_values, dropped, unexplained = {}, {}, {}, []
    alpha = settings.alpha_lack_of_fit / n_components
    late = (times > np.median(times)).astype(float)
    alpha_slow = getattr(settings, 'alpha_slow_structure', 0.0)
    for k, c in enumerate(components):
        fit = fits[k]
        found = per_component[k]
        unstable = _unstable(problem, k, comp_terms[k], fit, found, late, alpha)
        variance = fit.gls.rss / fit.gls.dof
        ratio, p = lack_of_fit(fit.gls, s2[k], nu[k])
        ratios[c], p_values[c] = float(ratio), p
        structure = lacks_fit(fit.gls, s2[k], nu[k], capacity[k], settings, n_components)
        directed, bases = None, {}
        if alpha_slow > 0:
            bases = slow_structure_bases(times, points.gravity, loads[:, k])
            directed = directed_lack_of_fit(
                problem, k, comp_terms[k], base_terms, bases, alpha_slow, n_components * len(bases)
            )
            if directed is not None:
                size = fit_columns(
                    np.hstack([problem.columns(comp_terms[k]), bases[directed[0]]]), loads[:, k]
                )
                if (
                    np.sqrt(max(fit.ols.rss - size.rss, 0.0) / len(loads)) / capacity[k] * 100.0
                    < settings.min_effect_pct_fs
                ):
                    directed = None
        if not (structure or unstable or directed):
            continue
        partly, explained_note = (), ''
        if found:
            base_excess = max(base_fits[k].gls.rss / base_fits[k].gls.dof - s2[k], 0.0)
            explained = 1.0 - max(variance - s2[k], 0.0) / base_excess if base_excess > 0 else 0.0
            if directed is not None:  # the excess along the directed basis (directed_lack_of_fit)
                explained = min(explained, directed[2]) if structure else directed[2]
            if unstable or explained < settings.min_explained:
                partly = tuple(e['candidate'].family for e in found)
                terms = set()
                for e in found:
                    terms |= set(e['candidate'].components[k]['added'])
                dropped[k] = terms
                fit = problem.fit(k, [t for t in comp_terms[k] if t not in terms])
                ratio, p = lack_of_fit(fit.gls, s2[k], nu[k])
                if unstable:
                    explained_note = (
                        '; '
                        + ', '.join(
                            f'{name} fitted it with coefficients that change over the '
                            f'campaign (first vs second half, p = {q:.1g})'
                            for name, q in unstable
                        )
                        + ': not adopted on '
                        + c
                    )
                else:
                    explained_note = (
                        f'; {", ".join(partly)} fitted only {explained:.0%} of the excess: '
                        'not adopted on ' + c
                    )
            else:
                explained_note = (
                    f'; left after {", ".join(e["candidate"].family for e in found)} '
                    f'(which explained {explained:.0%} of the excess)'
                )
        residual = fit.ols.residuals
        name, r, _ = _best_tracker(residual[loaded], trackers)
        track_values = None
        if name != 'nothing found':
            track_values = np.full(len(residual), np.nan)
            track_values[loaded] = trackers[name][:, 0]
        directed_note = ''
        if directed is not None:
            directed_note = (
                f'; the load shape of {c} (x, x², x|x|) changes with {directed[0]} '
                f'(directed test p = {directed[1]:.1g})'
            )
            if name == 'nothing found':
                name, r = f'load {c} × {directed[0]}', float('nan')
                # the structure itself: the residual's least-squares projection on the basis
                basis = bases[directed[0]]
                coefficients = minimum_norm_solve(basis[loaded], residual[loaded]).solution
                column = basis @ coefficients
                track_values = np.where(
                    loaded, column / max(float(np.max(np.abs(column[loaded]))), 1e-300), np.nan
                )
        sigma = float(sigma_pct_fs(residual, capacity[k]))
        evidence = (
            f'{c}: residual σ {np.sqrt(ratio):.1f}× the repeatability ({repeatability[c]:.3f} % '
            f'FS from {source[c]}; lack of fit p = {p:.1g})'
            + (
                f'; follows {name}' + (f' (r = {r:.2f})' if r == r else '')
                if name != 'nothing found'
                else '; follows nothing examined'
            )
            + directed_note
            + explained_note
        )
        unexplained.append(
            Unexplained(
                (c,),
                evidence,
                name,
                {c: sigma},
                float(ratio),
                p,
                r,
                partly,
                track_values,
                residual,
            )
        )
    return LackOfFit(
        repeatability, int(nu.min()), ratios, p_values, tuple(unexplained), warnings, dropped, roll
    )
