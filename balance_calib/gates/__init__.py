"""Acceptance gates of a calibration, from a bag campaign (refit) or a table (fit).

A calibration is written only when its data and its result look like one (interfaces.md,
report.json `acceptance` / `gates`). One Gate type and report (gate.py), one outlier rule
(outliers.py); the modules are split by what each gate judges:

    gate.py               Gate, ModelResiduals, gates_report, refusal and the priorities
    limits.py             the config's `acceptance:` limits over the defaults
    outputs.py            output_range, clipping, channels: the bridge outputs themselves
    sensitivity.py        sensitivity, active_calibration: the fitted sensitivities
    campaign.py           zero_points, body_weight, capacity, marker_order: a bag's load points
    schedule.py           schedule: the points found against the schedule run
    fit_quality.py        sigma, overfit, condition: the fitted model
    outlier_statistic.py  standardised leave-one-out residuals, robust σ, worst first
    outliers.py           the one outlier rule (explained by structure, alike)
    outlier_gates.py      outliers: the rule in a refit's and a table's words
    bags.py               a refit's gates in its order (data_gates, fit_gates)
"""
