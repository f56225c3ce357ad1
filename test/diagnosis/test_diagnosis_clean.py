"""Clean campaigns: the residual diagnosis finds nothing where there is nothing.

Cubic truth, Table 17 cubic noise, the memo's schedules, no effect: 20 seeds of each balance with
the repeatability from consecutive zero points alone, 10 more with the points' own samples (8 a
point) as the yardstick. No effect may be named, nothing may be `unexplained`, and no warning
raised (launchless_scripts/diagnosis_rates runs 50 other seeds per balance).
"""

import pytest

from balance_calib.diagnosis import diagnose
from balance_calib.simulation.diagnosis_rates import simulate_reduction


@pytest.mark.parametrize(
    'name, seeds, samples',
    [
        ('lmc6522', range(20), 1),
        ('b660h', range(20), 1),
        ('lmc6522', range(100, 110), 8),
        ('b660h', range(100, 110), 8),
    ],
)
def test_clean_campaigns_show_no_effect_and_nothing_unexplained(name, seeds, samples, request):
    config = request.getfixturevalue(name)
    found = {}
    for seed in seeds:
        reduction, scatter = simulate_reduction(
            config, seed=seed, samples_per_point=samples, with_scatter=True
        )
        result = diagnose(reduction, config, **(scatter if samples > 1 else {}))
        if result.effects or result.unexplained or result.warnings:
            found[seed] = (
                [e.evidence for e in result.effects],
                [u.evidence for u in result.unexplained],
                result.warnings,
            )
        assert result.sigma_pct_fs['after'] == result.sigma_pct_fs['before']
        assert result.adopted.term_names == result.base_fit.term_names
        assert set(result.repeatability_pct_fs) == set(config.components)
    assert found == {}
