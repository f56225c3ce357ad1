"""`reduce` takes the electrical zero a live balance_calibrator stated in the bag's /diagnostics
(its ~/zero, key `zero_mv` of its calibration status) when --electrical-zero-mv is not given: a
run recorded with the calibrator running (launchless_scripts/windon) reduces without the offset
warning, to the same coefficients as with the zero given by hand.
"""

from aero_cases import CONFIG, simulated_run, START_NS
import numpy as np

from balance_calib.aero.bag_io import parse_zero_mv, write_run_bag
from balance_calib.aero.pipeline import reduce_bags, ReduceOptions
from balance_calib.bags.messages import header, RELIABLE_QOS, typestore
from balance_calib.bags.writer import BagWriter, qos_profiles_yaml
from balance_calib.cli import main
from balance_calib.simulation.wind_on import wind_on_outputs

ZERO_MV = 0.04


def diagnostics_cdr(ns, statuses):
    """A DiagnosticArray of (name, hardware_id, {key: value}) statuses."""
    store = typestore()
    types = store.types
    array = types['diagnostic_msgs/msg/DiagnosticArray'](
        header=header(ns, ''),
        status=[
            types['diagnostic_msgs/msg/DiagnosticStatus'](
                level=0,
                name=name,
                message='',
                hardware_id=hardware,
                values=[
                    types['diagnostic_msgs/msg/KeyValue'](key=k, value=v)
                    for k, v in values.items()
                ],
            )
            for name, hardware, values in statuses
        ],
    )
    return store.serialize_cdr(array, 'diagnostic_msgs/msg/DiagnosticArray')


def zero_text(zero_mv):
    return ', '.join(
        f'{b}={v:+.5f}' for b, v in zip(('FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV'), zero_mv)
    )


def run_with_diagnostics(tmp_path, statuses_at):
    """The simulated run (0.04 mV zero on every bridge) and a second bag of /diagnostics."""
    profile, _ = simulated_run()
    raw = wind_on_outputs(
        CONFIG.matrices['cubic'], profile.loads_balance, electrical_zero_mv=ZERO_MV
    )
    stamps = START_NS + np.round(profile.times_s * 1e9).astype(np.int64)
    write_run_bag(tmp_path / 'run', stamps, raw, profile.support_attitude, profile.q_pa)
    with BagWriter(tmp_path / 'diagnostics') as writer:
        writer.add_topic(
            '/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', qos_profiles_yaml(RELIABLE_QOS)
        )
        for share, statuses in statuses_at:
            ns = int(stamps[0] + share * (stamps[-1] - stamps[0]))
            writer.write('/diagnostics', ns, diagnostics_cdr(ns, statuses))
    return [tmp_path / 'run', tmp_path / 'diagnostics']


def calibrator_status(zero_text_or_none, balance='LMC6522', node='balance_calibrator'):
    return (f'{node}: calibration', balance, {'model': 'cubic', 'zero_mv': zero_text_or_none})


def test_the_zero_parses_from_the_calibrators_own_text():
    assert np.allclose(
        parse_zero_mv(zero_text([0.04, -0.01, 0, 0, 0, 0.5])), [0.04, -0.01, 0, 0, 0, 0.5]
    )
    assert np.allclose(parse_zero_mv('FZV=+0.02000'), [0, 0, 0.02, 0, 0, 0])  # a partial one
    assert parse_zero_mv('none') is None
    assert parse_zero_mv('FXV=nan') is None


def test_the_zero_of_the_bags_diagnostics_is_subtracted_as_if_given(tmp_path, capsys):
    bags = run_with_diagnostics(
        tmp_path,
        [
            (0.0, [calibrator_status('none')]),  # before ~/zero: nothing stated
            (0.1, [calibrator_status(zero_text([ZERO_MV] * 6)), ('other: input', 'X', {})]),
            (0.9, [calibrator_status(zero_text([9.0] * 6), balance='B660H', node='left')]),
        ],
    )
    reduction = reduce_bags(bags, 'lmc6522', 'euler_replica_lmc6522')
    assert np.allclose(reduction.electrical_zero_mv, ZERO_MV)
    assert "balance_calibrator's ~/zero" in reduction.electrical_zero_source
    assert not any('offsets' in w for w in reduction.main.result.warnings)
    given = reduce_bags(
        bags, 'lmc6522', 'euler_replica_lmc6522', ReduceOptions(electrical_zero_mv=[ZERO_MV] * 6)
    )
    assert given.electrical_zero_source == '--electrical-zero-mv'
    ours = np.array([p.reduced.body for p in reduction.main.result.wind_on])
    by_hand = np.array([p.reduced.body for p in given.main.result.wind_on])
    assert np.max(np.abs(ours - by_hand)) < 1e-12

    out = tmp_path / 'out'
    args = ['reduce', *map(str, bags), '--calibration', 'lmc6522']
    assert main(args + ['--model', 'euler_replica_lmc6522', '--out', str(out)]) == 0
    console = capsys.readouterr().out
    assert 'warning' not in console
    assert 'electrical zero: FXV +0.04000' in console
    assert "(balance_calibrator's ~/zero, stated in the bag's /diagnostics)" in (
        (out / 'report.md').read_text()
    )


def test_a_zero_retaken_during_the_run_is_warned_and_the_first_kept(tmp_path):
    bags = run_with_diagnostics(
        tmp_path,
        [
            (0.1, [calibrator_status(zero_text([ZERO_MV] * 6))]),
            (0.6, [calibrator_status(zero_text([ZERO_MV + 0.01] * 6))]),
        ],
    )
    reduction = reduce_bags(bags, 'lmc6522', 'euler_replica_lmc6522')
    assert np.allclose(reduction.electrical_zero_mv, ZERO_MV)
    warnings = reduction.main.result.warnings
    assert any('changed during the run (by up to 0.01000 mV)' in w for w in warnings), warnings
