"""`balance-calib design --weights FILE`: added points rounded to the loads a rig's weight set
makes (coverage/weight_set.py). Expected values by hand from the weights and the LMC6522's lever
arms (TM-663 Appendix A: M_X from F_Z weights at 0.04 ... 0.20 m).
"""

import numpy as np
import pytest

from balance_calib.cli import main
from balance_calib.config import load_balance_config
from balance_calib.coverage.weight_set import (
    achievable_masses_kg,
    lever_arms_m,
    read_weight_set,
    round_to_weight_set,
    WeightSetError,
)
from balance_calib.units import STANDARD_GRAVITY_M_S2 as G


def test_achievable_sums_are_every_combination_of_the_weights():
    # two 5 kg and one 2 kg: 0, 2, 5, 7, 10, 12
    assert np.allclose(achievable_masses_kg([5.0, 2.0], [2, 1]), [0, 2, 5, 7, 10, 12])


def test_lmc6522_lever_arms_are_the_schedules_stations():
    arms = lever_arms_m(load_balance_config('lmc6522'))
    assert np.allclose(arms['MX'], [0.04, 0.08, 0.12, 0.16, 0.20])
    assert np.allclose(arms['MY'], [0.05, 0.10, 0.15, 0.20])


def test_forces_and_moments_round_to_the_nearest_load_the_set_makes():
    config = load_balance_config('lmc6522')
    masses, counts = np.array([10.0, 1.0]), np.array([3, 4])  # sums 0-4, 10-14, 20-24, 30-34 kg
    wanted = np.array([[-127.0, 0.0, 2.0 * G * 14.2, 0.0, 0.0, 0.0]])
    # F_X: 127 N = 12.95 kg -> 13 kg; F_Z: 14.2 kg -> 14 kg
    wanted[0, 3] = 15.3 * G * 0.12  # M_X: 15.3 kg at 0.12 m = 1.836 kgf·m
    rounded, notes = round_to_weight_set(wanted, config, masses, counts)
    assert rounded[0, 0] == pytest.approx(-13 * G)
    assert rounded[0, 2] == pytest.approx(30 * G)  # 28.4 kg: 24 or 30 makeable, 30 nearer
    # nearest of (sum kg) x arm: 1.836 -> 23 kg x 0.08 = 1.84 kgf·m (15 x 0.12 = 1.80 is farther)
    assert rounded[0, 3] == pytest.approx(23 * 0.08 * G)
    assert notes == []
    too_much = np.array([[0.0, 0.0, 50 * G, 0.0, 0.0, 0.0]])
    rounded, notes = round_to_weight_set(too_much, config, masses, counts)
    assert rounded[0, 2] == pytest.approx(34 * G) and 'FZ' in notes[0] and 'only' in notes[0]


@pytest.mark.parametrize(
    'text, problem',
    [
        ('name,mass,count\nA,1,1\n', 'no column mass_kg'),
        ('name,mass_kg,count\nA,x,1\n', 'row 1: mass_kg and count must be numbers'),
        ('name,mass_kg,count\nA,1,1.5\n', 'row 1: count 1.5 must be a whole number'),
        ('name,mass_kg,count\nA,-1,1\n', 'row 1: mass_kg -1 must be at least'),
        ('name,mass_kg,count\nA,1,0\n', 'no weights'),
    ],
)
def test_a_bad_weights_file_is_refused_naming_the_row(tmp_path, text, problem):
    path = tmp_path / 'weights.csv'
    path.write_text(text)
    with pytest.raises(WeightSetError, match=problem):
        read_weight_set(path)


def test_design_with_weights_adds_only_loads_the_set_makes(tmp_path, capsys):
    (tmp_path / 'env.csv').write_text(
        'FX,FY,FZ,MX,MY,MZ\n-300,100,-3000,10,150,20\n-400,200,-5000,20,250,40\n'
    )
    (tmp_path / 'w.csv').write_text('name,mass_kg,count\nW50,50,6\nW20,20,4\nW5,5,4\n')
    out = tmp_path / 'des'
    args = ['design', '--balance', 'lmc6522', '--envelope', str(tmp_path / 'env.csv')]
    assert (
        main(args + ['--points', '4', '--weights', str(tmp_path / 'w.csv'), '--out', str(out)])
        == 0
    )
    rows = np.loadtxt(out / 'schedule.csv', delimiter=',', skiprows=1, usecols=range(9))
    added = rows[328:, 3:9]  # kgf and kgf·m, after the LMC6522's 328 points
    assert len(added) and np.any(added != 0)
    forces = added[:, :3]
    assert np.allclose(forces / 5.0, np.round(forces / 5.0))  # every force a sum of 5 kg steps
    # M_X = (5 kg steps) x (one of the schedule's arms)
    arms = np.array([0.04, 0.08, 0.12, 0.16, 0.20])
    for moment in added[:, 3]:
        assert np.any(
            np.isclose(np.abs(moment) / arms / 5.0, np.round(np.abs(moment) / arms / 5.0))
        )
