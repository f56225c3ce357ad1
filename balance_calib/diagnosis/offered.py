"""The families a diagnosis offers (diagnose.py) and the variables their terms use: what the
settings ask for and the points allow (a temperature that changes, times that span a campaign,
more than one orientation for the tare), the load directions and |load| from the base fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.terms import as_variables, design_matrix, parse_terms
from ..model.tm663 import tm663_terms
from ..tare.calibration_body import tare_loads
from .candidates import (
    absolute_load_variables,
    bidirectional_family,
    BridgeOutputs,
    CandidateFamily,
    creep_family,
    creep_time_constants,
    creep_variables,
    cross_terms_family,
    direction_variables,
    drift_family,
    drift_frequencies,
    drift_variables,
    excitation_basis,
    excitation_family,
    excitation_variables,
    hysteresis_family,
    temperature_family,
    without_base_terms,
)
from .statistics import fit_columns


@dataclass(frozen=True)
class Offered:
    base_terms: list  # term names of the base model
    variables: dict  # name -> (N,) values of the extra variables the families' terms use
    families: list  # [CandidateFamily], base terms removed
    reference_temperature: float | None  # °C, the mean (dT = T - it), None without temperature
    raw_direction: np.ndarray  # (N, 6) raw ±1 load history
    tare_available: bool  # the tare is examined (asked for, more than one orientation)
    skipped: dict  # effect -> why it is not examined


def families_offered(reduction, config, base_model, times, temps, settings) -> Offered:
    """The families offered to the search over `reduction`'s corrected points; times (s), temps
    (°C) per point.
    """
    points = reduction.points
    components, outputs_names = tuple(config.components), tuple(config.bridge_outputs)
    capacity = np.asarray(config.capacity, dtype=float)
    n_points = len(points.label)
    corrected = reduction.corrected
    skipped: dict[str, str] = {}

    base_terms = [t.name for t in tm663_terms(base_model, outputs_names)]
    variables: dict[str, np.ndarray] = {}
    families: list[CandidateFamily] = []
    wanted = set(settings.effects)
    reference_temperature = None
    if 'temperature' in wanted:
        if temps.shape == (n_points,) and np.all(np.isfinite(temps)) and np.ptp(temps) > 1e-6:
            reference_temperature = float(np.mean(temps))
            variables['dT'] = temps - reference_temperature
            families.append(temperature_family(outputs_names))
        else:
            skipped['temperature'] = 'no balance temperature per point (or it never changed)'
    if 'zero_drift' in wanted:
        frequencies = drift_frequencies(times, settings.drift_oversampling)
        if len(frequencies):
            variables.update(
                drift_variables(times, frequencies, points.is_zero_point, points.orientation)
            )
            families.append(drift_family(frequencies, settings.max_terms.get('zero_drift', 8)))
        else:
            skipped['zero_drift'] = 'point times do not span a campaign'
    # loads as the base model fits them from the outputs: what a term keyed to the load may use
    # (built from the applied loads themselves, the target, it would fit part of the target and not
    # the effect)
    base_design = design_matrix(
        parse_terms(base_terms), as_variables(outputs_names, corrected.bridge_outputs_mv), n_points
    )
    fitted_loads = np.column_stack(
        [
            base_design @ fit_columns(base_design, corrected.loads[:, k]).coefficients
            for k in range(len(components))
        ]
    )
    directions, raw_direction = direction_variables(
        corrected.loads,
        times,
        capacity,
        components,
        points.is_zero_point,
        points.orientation,
        BridgeOutputs(corrected.bridge_outputs_mv, outputs_names, config.rated_output_mv),
        fitted_loads,
    )
    if 'hysteresis' in wanted:
        variables.update(directions)
        families.append(hysteresis_family(components, outputs_names))
    if 'bidirectional' in wanted:
        variables.update(absolute_load_variables(fitted_loads, capacity, components))
        families.append(bidirectional_family(outputs_names, components))
    if 'creep' in wanted:
        taus = creep_time_constants(times)
        variables.update(
            creep_variables(
                points.outputs_mv,
                times,
                taus,
                outputs_names,
                points.is_zero_point,
                points.orientation,
            )
        )
        families.append(creep_family(outputs_names, taus, settings.max_terms.get('creep', 2)))
    if 'excitation' in wanted:
        basis, basis_labels = excitation_basis(times)
        total = np.asarray(corrected.loads, float) + tare_loads(reduction.body, points.gravity)
        variables.update(
            excitation_variables(
                basis, total, components, points.is_zero_point, times, points.orientation
            )
        )
        families.append(
            excitation_family(components, basis_labels, settings.max_terms.get('excitation', 4))
        )
    if 'cross_terms' in wanted:
        families.append(
            cross_terms_family(outputs_names, base_terms, settings.max_terms.get('cross_terms', 4))
        )
    families = [without_base_terms(f, base_terms) for f in families]
    tare_available = 'tare' in wanted and len(np.unique(np.round(points.gravity, 6), axis=0)) >= 2
    if 'tare' in wanted and not tare_available:
        skipped['tare'] = 'a single orientation: the body weight cannot be told from the constant'
    return Offered(
        base_terms,
        variables,
        families,
        reference_temperature,
        raw_direction,
        tare_available,
        skipped,
    )
