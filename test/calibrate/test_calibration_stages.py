"""The one order every calibration runs in (calibration_stages.run_stages), for bags and tables.

A recording side shows the order and where a failed gate stops the run; then the two real sides:
a table whose written output capacities are ten times its bridges' response is refused by its
sensitivity gate before the loop is closed on it (the diagnosis never runs), and forced it runs
every stage and reports every gate; a simulated campaign refused by its schedule gate never
reaches the diagnosis either.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from table_cases import six_component_balance

from balance_calib.calibrate.path import calibrate
from balance_calib.calibration_settings import CalibrationSettings
from balance_calib.calibration_stages import run_stages
from balance_calib.config import load_balance_config
from balance_calib.gates.gate import Gate, refusal
from balance_calib.refit.bag_points import load_points_record, reduced_points
from balance_calib.refit.errors import RefitError
from balance_calib.tables.calibrate import calibrate_table
from balance_calib.tables.errors import TableCalibrationError
from balance_calib.tables.table_points import table_calibration_points


class Refused(Exception):
    pass


class Recording:
    """A side whose gates fail where a test says; it records the stages called."""

    where = 'rig.csv'
    priority = ('b', 'a')
    names_others = True

    def __init__(self, failing: dict[str, tuple[str, ...]]):
        self.failing, self.calls = failing, []

    def refused(self, message):
        return Refused(message)

    def _gates(self, stage, names):
        self.calls.append(stage)
        return [Gate(n, n not in self.failing.get(stage, ()), f'{n} says why') for n in names]

    def screen(self):
        return self._gates('screen', ('s',))

    def fit(self):
        self.calls.append('fit')

    def data_gates(self):
        return self._gates('data_gates', ('a', 'b', 'c'))

    def diagnose(self):
        self.calls.append('diagnose')

    def fit_gates(self):
        return self._gates('fit_gates', ('d',))

    def result(self, gates, forced):
        self.calls.append('result')
        return [g.name for g in gates], forced


ALL = ['screen', 'fit', 'data_gates', 'diagnose', 'fit_gates', 'result']


def test_the_stages_run_in_the_one_order_and_a_failure_stops_at_its_stage():
    side = Recording({})
    assert run_stages(side, force=False) == (['s', 'a', 'b', 'c', 'd'], False)
    assert side.calls == ALL

    side = Recording({'data_gates': ('a', 'b', 'c')})
    said = []
    with pytest.raises(Refused) as refused:
        run_stages(side, force=False, progress=said.append)
    assert side.calls == ['screen', 'fit', 'data_gates']  # no diagnosis, no fit gates
    # the priority names b first, then a; c, which it does not name, last
    assert str(refused.value) == (
        'rig.csv: refused by acceptance gate b: b says why (also failed: a, c); '
        'nothing written (--force writes it anyway)'
    )
    assert said[1:4] == [
        'gate a: FAILED: a says why',
        'gate b: FAILED: b says why',
        'gate c: FAILED: c says why',
    ]

    side = Recording({'screen': ('s',)})
    with pytest.raises(Refused):
        run_stages(side, force=False)
    assert side.calls == ['screen']

    side = Recording({'screen': ('s',), 'fit_gates': ('d',)})
    assert run_stages(side, force=True) == (['s', 'a', 'b', 'c', 'd'], True)
    assert side.calls == ALL


def test_a_refusal_names_the_others_only_when_the_side_does():
    gates = [Gate('x', False, 'x why'), Gate('y', False, 'y why'), Gate('z', True, 'fine')]
    assert refusal('t.csv', gates, ('y', 'x'), names_others=False) == (
        't.csv: refused by acceptance gate y: y why; nothing written (--force writes it anyway)'
    )
    assert 'also failed: x)' in refusal('t.csv', gates, ('y', 'x'), names_others=True)
    assert refusal('t.csv', gates[2:], ('y', 'x'), names_others=True) is None


@pytest.fixture(scope='module')
def mislabelled():
    """A table whose output capacities are written ten times too large (a unit slip)."""
    table, _ = six_component_balance(np.random.default_rng(11))
    return replace(table, output_capacity=table.output_capacity * 10.0)


def test_a_table_refused_by_its_data_gates_is_never_diagnosed(mislabelled, monkeypatch):
    import balance_calib.tables.calibrate as module

    def no_diagnosis(*args, **kwargs):
        raise AssertionError('the loop was closed on a refused table')

    monkeypatch.setattr(module, 'close_the_loop', no_diagnosis)
    with pytest.raises(TableCalibrationError, match='refused by acceptance gate sensitivity'):
        calibrate_table(mislabelled, statistics=False)


def test_a_forced_table_runs_every_stage_and_reports_every_gate(mislabelled):
    result = calibrate(table_calibration_points(mislabelled), CalibrationSettings(force=True))
    names = [g['name'] for g in result.report['gates']]
    assert names == ['channels', 'sensitivity', 'outliers', 'overfit', 'condition']
    failed = [g['name'] for g in result.report['gates'] if not g['passed']]
    assert failed == ['sensitivity'] and result.report['forced'] is True
    assert 'effects' in result.report  # the loop was closed on it


def test_a_campaign_refused_by_its_data_gates_is_never_diagnosed(campaigns, monkeypatch):
    """LMC6522's campaign judged against B660H's config: the sensitivity gate refuses it before
    the diagnosis; forced, the diagnosis runs and every gate is reported.
    """
    import balance_calib.refit.pipeline as module

    config = load_balance_config('b660h')
    points = reduced_points(load_points_record(campaigns.points(seed=5)), config)
    ran = []
    real = module._run_diagnosis
    monkeypatch.setattr(module, '_run_diagnosis', lambda *a, **k: ran.append(1) or real(*a, **k))
    with pytest.raises(RefitError, match='refused by acceptance gate sensitivity'):
        calibrate(points, CalibrationSettings())
    assert ran == []
    forced = calibrate(points, CalibrationSettings(force=True))
    assert ran == [1]
    names = [g['name'] for g in forced.report['acceptance']['gates']]
    assert names[0] == 'output_range' and names[-2:] == ['sigma', 'outliers'], names
    assert forced.report['acceptance']['forced'] is True
