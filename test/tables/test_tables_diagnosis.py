"""The loop closes on table data too: residuals examined against point order, load direction and
extra channels; a drift or a hysteresis put into a generated table is named, a clean one gives
nothing, and what cannot be examined without bag inputs is said.
"""

import numpy as np
import pytest

from balance_calib.tables import synthetic as sy
from balance_calib.tables.calibrate import calibrate_table
from balance_calib.tables.diagnose_table import load_direction


def _campaign(seed, effect=None):
    rng = np.random.default_rng(seed)
    truth = sy.direct_truth(rng, nonlinear_fraction=0.01)
    schedule = sy.support_schedule(rng, 21, 40)
    tares = sy.tares_for(rng, np.unique(schedule.series))
    applied, outputs = sy.direct_campaign(rng, truth, schedule, tares, 0.0002 * sy.capacity_si())
    if effect == 'drift':  # F_X bridge zero creeping by 1 % of rated output over the table
        outputs[:, 0] += np.linspace(0, 1e-2, len(outputs)) * sy.RATED_OUTPUT_MV[0]
    if effect == 'hysteresis':  # M_Y bridge reads 0.05 % of rated output higher when unloading
        direction = load_direction(applied, schedule.series, sy.capacity_si())
        outputs[:, 4] -= 5e-4 * sy.RATED_OUTPUT_MV[4] * direction
    return calibrate_table(
        sy.make_table(applied, outputs, schedule.series), method='direct', statistics=False
    ).report


def test_load_direction_by_hand():
    applied = np.array([[0, 0], [1, 0], [2, 0], [1, 0], [0, 5], [0, 3]], float)
    series = np.array([1, 1, 1, 1, 2, 2])
    assert load_direction(applied, series, np.array([2.0, 5.0])).tolist() == [0, 1, 1, -1, 0, -1]


@pytest.mark.parametrize('seed', [1, 2])
def test_clean_tables_leave_nothing_unexplained(seed):
    report = _campaign(seed)
    assert report['unexplained'] == []
    assert set(report['diagnosis']['examined']) == {'point order', 'load direction'}
    assert (
        'temperature' in report['diagnosis']['skipped']
        and 'creep' in report['diagnosis']['skipped']
    )


@pytest.mark.parametrize(
    'effect, component, tracks',
    [('drift', 'FX', 'point order'), ('hysteresis', 'MY', 'load history')],
)
def test_a_drift_or_hysteresis_is_named(effect, component, tracks):
    report = _campaign(3, effect)
    found = [u for u in report['unexplained'] if u['tracks'] == tracks]
    assert found and component in found[0]['components'], report['unexplained']
    assert all(u['tracks'] == tracks for u in report['unexplained'])
