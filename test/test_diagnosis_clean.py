"""Clean campaigns: the residual diagnosis finds nothing where there is nothing (issue 4).

Cubic truth, Table 17 cubic noise, the memo's schedules, no effect: 20 seeds of each balance
(launchless_scripts/diagnosis_rates runs other seeds and prints the rate next to the detection table).
"""
import pytest

from balance_calib.diagnosis import diagnose
from balance_calib.diagnosis.rates import simulate_reduction


@pytest.mark.parametrize('name, seeds', [('lmc6522', range(20)), ('b660h', range(20))])
def test_clean_campaigns_show_no_effect(name, seeds, request):
    config = request.getfixturevalue(name)
    found = {}
    for seed in seeds:
        result = diagnose(simulate_reduction(config, seed=seed), config)
        if result.effects:
            found[seed] = [e.evidence for e in result.effects]
        assert result.sigma_pct_fs['after'] == result.sigma_pct_fs['before']
        assert result.adopted.term_names == result.base_fit.term_names
    assert found == {}
