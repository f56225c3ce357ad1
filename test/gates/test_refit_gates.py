"""Acceptance gates of the refit: each way a campaign can be wrong is refused by the gate that
names it, a clean campaign passes every gate, --force writes and says so, and a campaign split
over two sessions hours apart refits like the unsplit one with the same memory.
"""

from dataclasses import replace
import json
import subprocess
import sys
import tracemalloc

import numpy as np
import pytest
import yaml

from balance_calib.benchmarks.refit_reliability import (
    _copy_events,
    calibration_error_pct_fs,
    campaign_events,
    Event,
    GRAVITY,
    KGF_N,
    LBF_N,
    LOAD,
    Mutant,
    RAW,
    small_campaign,
    write_mcap,
)
from balance_calib.calibrate.from_bags import RefitSettings, run_refit
from balance_calib.calibration_file import load_calibration
from balance_calib.config import load_balance_config
from balance_calib.refit.pipeline import RefitError


@pytest.fixture(scope='module')
def clean():
    campaign = small_campaign('lmc6522', seed=3)
    return campaign, tuple(campaign_events(campaign))


def _load_events(events):
    return [i for i, e in enumerate(events) if e.topic == LOAD and not np.all(np.isnan(e.values))]


def _refit(tmp_path, events, *, balance='lmc6522', force=False, **kwargs):
    tmp_path.mkdir(parents=True, exist_ok=True)
    bag = write_mcap(events, tmp_path / 'campaign.mcap')
    return run_refit(
        [bag],
        balance,
        tmp_path / 'out',
        RefitSettings(diagnose=False, plots=False, force=force, **kwargs),
    )


def _gates(result):
    return {g['name']: g for g in result.report['acceptance']['gates']}


def test_a_clean_campaign_passes_every_gate_and_the_report_shows_them(clean, tmp_path):
    campaign, events = clean
    result = _refit(tmp_path, events)
    gates = _gates(result)
    assert set(gates) == {
        'output_range',
        'sigma',
        'outliers',
        'sensitivity',
        'zero_points',
        'body_weight',
        'capacity',
        'clipping',
        'marker_order',
        'schedule',
    }
    assert all(g['passed'] for g in gates.values()), [
        g['reason'] for g in gates.values() if not g['passed']
    ]
    assert result.report['acceptance'] == {
        **result.report['acceptance'],
        'passed': True,
        'forced': False,
    }
    # the fitted linear sensitivities are the truth's (Table 10): noise moves them by far less than
    # 1 %
    assert all(abs(r - 1) < 0.01 for r in gates['sensitivity']['ratio'].values())
    assert '## Acceptance gates' in (tmp_path / 'out' / 'report.md').read_text()
    mutant = Mutant('clean', 'clean', [], 'lmc6522', 'lmc6522', campaign)
    assert np.all(calibration_error_pct_fs(result.calibration, mutant) < 0.1)


def test_loads_recorded_in_kgf_are_refused_by_the_sensitivities(clean, tmp_path):
    events = _copy_events(clean[1])
    for i in _load_events(events):
        events[i].values = events[i].values / KGF_N
    with pytest.raises(RefitError) as error:
        _refit(tmp_path, events)
    message = str(error.value)
    assert (
        'campaign.mcap' in message
        and 'acceptance gate sensitivity' in message
        and '\n' not in message
    )
    assert 'kgf?' in message
    assert not (tmp_path / 'out' / 'calibration.yaml').exists()
    # forced, the ratio is 1/g: loads 9.81x too small need a 9.81x smaller N per mV
    gates = _gates(_refit(tmp_path, events, force=True))
    assert all(
        r == pytest.approx(1 / KGF_N, rel=0.01) for r in gates['sensitivity']['ratio'].values()
    )


def test_outputs_recorded_in_volts_are_refused_before_any_fit(clean, tmp_path):
    events = _copy_events(clean[1])
    for event in events:
        if event.topic == RAW:
            event.values = event.values / 1000.0
    with pytest.raises(
        RefitError,
        match=r'acceptance gate output_range: .*FXV 0\.00\d+ mV of 1\.908.*V instead of mV',
    ):
        _refit(tmp_path, events)


def test_the_wrong_balance_config_is_refused(clean, tmp_path):
    with pytest.raises(RefitError, match='acceptance gate sensitivity: .*B660H'):
        _refit(tmp_path, clean[1], balance='b660h')


def test_a_calibration_far_from_the_active_one_is_refused(clean, tmp_path):
    config = load_balance_config('lmc6522')
    # the shipped matrices are this simulation's truth: the refit stays within 5 % of them
    result = _refit(tmp_path, clean[1], active_calibration=config.path)
    assert _gates(result)['active_calibration']['passed']
    # an active calibration 8 % more sensitive in every component is not this balance any more
    active = load_calibration(config.path)
    scaled = replace(
        active,
        models={
            name: model.with_coefficients(np.asarray(model.coefficients) * 1.08)
            for name, model in active.models.items()
        },
    )
    with pytest.raises(RefitError, match=r'acceptance gate active_calibration: .*×0\.92'):
        _refit(tmp_path, clean[1], active_calibration=scaled)


def test_one_wrong_weight_is_flagged_at_its_point(clean, tmp_path):
    events = _copy_events(clean[1])
    capacity = load_balance_config('lmc6522').capacity
    loads = _load_events(events)
    # the point with the largest single load relative to capacity: a 10 % typo is ~10 % FS there,
    # hundreds of times the point noise (Table 17's cubic σ, < 0.1 % FS)
    fraction = np.array([np.max(np.abs(events[i].values) / capacity) for i in loads])
    which = int(np.argmax(fraction))
    component = int(np.argmax(np.abs(events[loads[which]].values) / capacity))
    events[loads[which]].values[component] *= 1.1
    result = _refit(tmp_path, events, force=True)
    outliers = _gates(result)['outliers']
    assert not outliers['passed']
    assert outliers['points'][0]['point'] == which + 1
    assert (
        outliers['points'][0]['component'] == load_balance_config('lmc6522').components[component]
    )
    assert f'point {which + 1} ' in outliers['reason']
    report = json.loads((tmp_path / 'out' / 'report.json').read_text())
    assert report['acceptance']['forced'] is True and report['acceptance']['passed'] is False
    assert 'WRITTEN WITH --force' in (tmp_path / 'out' / 'report.md').read_text()
    assert (
        load_calibration(tmp_path / 'out' / 'calibration.yaml').extra['acceptance']['forced']
        is True
    )


def test_a_clipped_bridge_is_refused_naming_it(clean, tmp_path):
    events = _copy_events(clean[1])
    raw = [i for i, e in enumerate(events) if e.topic == RAW]
    column = np.array([events[i].values[2] for i in raw])
    limit = float(np.quantile(column, 0.95))  # F_ZV saturates on its top 5 %
    for i in raw:
        events[i].values[2] = min(events[i].values[2], limit)
    with pytest.raises(
        RefitError, match=r'acceptance gate clipping: bridge FZV is flat-topped at'
    ):
        _refit(tmp_path, events)


def test_markers_out_of_time_order_are_refused(clean, tmp_path):
    events = _copy_events(clean[1])
    loads = _load_events(events)
    first, second = events[loads[40]], events[loads[42]]
    first.stamp_ns, second.stamp_ns = second.stamp_ns, first.stamp_ns
    with pytest.raises(RefitError, match='acceptance gate (marker_order|sigma|outliers)') as error:
        _refit(tmp_path, events)
    assert 'marker_order' in str(error.value)


def test_a_lost_gravity_message_is_refused_by_the_zero_points(clean, tmp_path):
    events = list(clean[1])
    gravity = [i for i, e in enumerate(events) if e.topic == GRAVITY]
    del events[gravity[3]]
    with pytest.raises(RefitError, match='acceptance gate zero_points: zero points .* differ by'):
        _refit(tmp_path, events)


def test_a_negative_or_reversed_body_is_refused(clean, tmp_path):
    config = load_balance_config('lmc6522')
    data = yaml.safe_load(config.path.read_text())
    data['calibration_body']['weight_n'] = -669.44
    negative = tmp_path / 'negative.yaml'
    negative.write_text(yaml.safe_dump(data))
    with pytest.raises(
        RefitError, match=r'acceptance gate body_weight: declared calibration body weight -669'
    ):
        _refit(tmp_path, clean[1], balance=negative)
    events = _copy_events(clean[1])
    for event in events:
        if event.topic == GRAVITY:
            event.values = -event.values
    with pytest.raises(
        RefitError, match=r'acceptance gate body_weight: calibration body weight -6\d\d'
    ):
        _refit(tmp_path, events)


def test_loads_beyond_capacity_are_refused(clean, tmp_path):
    events = _copy_events(clean[1])
    for i in _load_events(events):
        events[i].values = events[i].values * LBF_N  # lbf numbers taken for N the other way round
    with pytest.raises(
        RefitError, match=r'acceptance gate sensitivity: .*also failed: .*capacity'
    ):
        _refit(tmp_path, events)


def test_scatter_beyond_the_sigma_limit_is_refused(tmp_path, campaigns):
    # 0.5 % FS of point noise: σ after the zero points ≈ 0.5 × 1.11 (zero_point_noise_factor) >
    # 0.25
    events = campaign_events(campaigns.campaign('b660h', seed=2, noise=0.5))
    with pytest.raises(
        RefitError, match=r'acceptance gate sigma: σ of the base model beyond its limit'
    ):
        run_refit(
            [write_mcap(events, tmp_path / 'noisy.mcap', frame='B660H')],
            'b660h',
            tmp_path / 'out',
            RefitSettings(diagnose=False, plots=False),
        )


def test_the_cli_exits_2_with_one_line_and_force_writes(clean, tmp_path):
    bag = write_mcap(clean[1], tmp_path / 'campaign.mcap')
    out = tmp_path / 'out'
    refused = subprocess.run(
        [
            sys.executable,
            '-m',
            'balance_calib.cli',
            'refit',
            str(bag),
            '--balance',
            'b660h',
            '--out',
            str(out),
            '--no-diagnosis',
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert refused.returncode == 2 and len(refused.stderr.strip().splitlines()) == 1
    assert 'campaign.mcap' in refused.stderr and 'gate sensitivity' in refused.stderr
    assert not out.exists()
    forced = subprocess.run(
        [
            sys.executable,
            '-m',
            'balance_calib.cli',
            'refit',
            str(bag),
            '--balance',
            'b660h',
            '--out',
            str(out),
            '--no-diagnosis',
            '--force',
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert forced.returncode == 0 and 'written with --force' in forced.stderr
    assert json.loads((out / 'report.json').read_text())['acceptance']['forced'] is True
    assert {oct(p.stat().st_mode & 0o777) for p in out.iterdir()} == {'0o644'}


def _split(events, at, pause_ns):
    later = [
        Event(e.log_ns + pause_ns, e.order, e.topic, e.stamp_ns + pause_ns, e.values)
        for e in events[at:]
    ]
    last_gravity = [e for e in events[:at] if e.topic == GRAVITY][-1]
    later.insert(
        0, Event(later[0].log_ns - 1, 0, GRAVITY, later[0].stamp_ns - 1, last_gravity.values)
    )
    return list(events[:at]), later


def _peak_bytes(function):
    tracemalloc.start()
    try:
        result = function()
        return result, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_a_campaign_split_by_hours_refits_like_the_unsplit_one_in_the_same_memory(clean, tmp_path):
    campaign, events = clean
    whole = write_mcap(events, tmp_path / 'whole.mcap')
    unsplit, unsplit_peak = _peak_bytes(
        lambda: run_refit(
            [whole], 'lmc6522', tmp_path / 'o', RefitSettings(diagnose=False, plots=False)
        )
    )
    at = _load_events(events)[170]
    for hours in (1, 16):
        first, second = _split(events, at, hours * 3600 * 10**9)
        paths = [
            write_mcap(first, tmp_path / f'a{hours}.mcap'),
            write_mcap(second, tmp_path / f'b{hours}.mcap'),
        ]
        split, split_peak = _peak_bytes(
            lambda: run_refit(
                paths,
                'lmc6522',
                tmp_path / f'o{hours}',
                RefitSettings(diagnose=False, plots=False),
            )
        )
        assert split.report['sessions']['count'] == 2
        assert split.report['sessions']['pauses_s'][0] == pytest.approx(hours * 3600, abs=2)
        # same points, same samples: the loads of both calibrations agree far inside the noise
        config = load_balance_config('lmc6522')
        outputs = campaign.raw_mv[campaign.sample_point >= 0]
        difference = (
            (
                split.calibration.model('cubic').loads(outputs)
                - unsplit.calibration.model('cubic').loads(outputs)
            )
            / config.capacity
            * 100
        )
        assert np.max(np.abs(difference)) < 0.005
        # memory follows the messages, not the hours between them
        assert split_peak < 1.3 * unsplit_peak


def test_salvage_refits_what_is_intact_and_the_report_says_what_was_lost(clean, tmp_path):
    bag = write_mcap(clean[1], tmp_path / 'campaign.mcap')
    from mcap.reader import make_reader

    with open(bag, 'rb') as stream:
        chunks = sorted(
            make_reader(stream).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset
        )
    # a chunk without a gravity message: losing one of those is refused (test above), rightly
    gravity_ns = [e.log_ns for e in clean[1] if e.topic == GRAVITY]
    victim = next(
        c
        for c in chunks[len(chunks) // 2 :]
        if not any(c.message_start_time <= t <= c.message_end_time for t in gravity_ns)
    )
    data = bytearray(bag.read_bytes())
    middle = victim.chunk_start_offset + victim.chunk_length // 2
    data[middle] ^= 0xFF
    bag.write_bytes(bytes(data))
    with pytest.raises(
        RefitError, match=f'campaign.mcap: damaged data at byte offset {victim.chunk_start_offset}'
    ):
        run_refit([bag], 'lmc6522', tmp_path / 'out', RefitSettings(diagnose=False, plots=False))
    result = run_refit(
        [bag],
        'lmc6522',
        tmp_path / 'out',
        RefitSettings(diagnose=False, plots=False, salvage=True),
    )
    lost = result.report['bag_integrity']['lost']
    assert result.report['bag_integrity']['salvaged'] is True
    assert any(f'byte offset {victim.chunk_start_offset}' in line for line in lost)
    assert (
        f'byte offset {victim.chunk_start_offset}' in (tmp_path / 'out' / 'report.md').read_text()
    )
    mutant = Mutant('salvaged', 'salvaged', [bag], 'lmc6522', 'lmc6522', clean[0])
    assert np.all(calibration_error_pct_fs(result.calibration, mutant) < 0.1)


def test_out_is_checked_before_any_work(tmp_path):
    afile = tmp_path / 'afile'
    afile.write_text('not a directory')
    # the bag does not even exist: the --out problem is found first
    with pytest.raises(RefitError, match=f'{afile}: --out exists and is not a directory'):
        run_refit([tmp_path / 'missing.mcap'], 'lmc6522', afile)
    with pytest.raises(RefitError, match='/proc/refit-out: output directory not writable'):
        run_refit([tmp_path / 'missing.mcap'], 'lmc6522', '/proc/refit-out')


def _without_markers(events, share, seed, *, component=None):
    """The events less `share` of the load markers (chosen at random; of points loading `component`
    only, when given): their samples then belong to no point, as when the recorder lost them.
    """
    loads = _load_events(events)
    if component is not None:
        loads = [i for i in loads if abs(events[i].values[component]) > 0]
    rng = np.random.default_rng(seed)
    drop = set(rng.choice(loads, size=int(round(share * len(loads))), replace=False).tolist())
    return [e for i, e in enumerate(events) if i not in drop], len(drop)


def test_a_campaign_that_lost_30_percent_of_its_points_is_refused_with_counts(
    clean, tmp_path, capsys
):
    from balance_calib.cli import main

    events, dropped = _without_markers(clean[1], 0.30, seed=1)
    expected = len(load_balance_config('lmc6522').schedule)
    bag = write_mcap(events, tmp_path / 'damaged.mcap')
    out = tmp_path / 'out'
    status = main(['refit', str(bag), '--balance', 'lmc6522', '--out', str(out), '--no-diagnosis'])
    error = capsys.readouterr().err.strip()
    assert status == 2 and '\n' not in error, error
    assert 'damaged.mcap' in error and 'acceptance gate schedule' in error
    found = expected - dropped
    assert f'{found} of the {expected} scheduled points found ({dropped} missing, 30 %' in error
    assert 'lost coverage: FX' in error and '--force' in error
    assert not out.exists()
    # --force writes it, and the report keeps the counts
    result = _refit(tmp_path, events, force=True)
    gate = _gates(result)['schedule']
    assert not gate['passed'] and gate['missing'] == dropped and gate['expected'] == expected
    loads_fx = load_balance_config('lmc6522').schedule.loads[:, 0]
    assert gate['coverage']['FX']['expected'] == np.count_nonzero(loads_fx)


def test_two_percent_lost_passes_with_a_warning_and_a_complete_campaign_without(clean, tmp_path):
    events, dropped = _without_markers(clean[1], 0.02, seed=2)
    assert dropped >= 5
    result = _refit(tmp_path, events)
    gate = _gates(result)['schedule']
    assert gate['passed'] and gate['missing'] == dropped
    warning = f"{dropped} of the schedule's 328 points are missing"
    assert any(warning in w for w in result.report['warnings'])
    complete = _refit(tmp_path / 'complete', clean[1])
    assert _gates(complete)['schedule']['missing'] == 0
    assert not any('missing' in w for w in complete.report['warnings'])


def test_a_component_that_lost_its_loads_is_named_though_few_points_are_missing(clean, tmp_path):
    config = load_balance_config('lmc6522')
    mz = config.components.index('MZ')
    # 40 % of the points loading MZ lost: under 10 % of the campaign, beyond 20 % of MZ's coverage
    events, dropped = _without_markers(clean[1], 0.4, seed=3, component=mz)
    full = _gates(_refit(tmp_path / 'full', clean[1]))['schedule']
    expected_mz = full['coverage']['MZ']['expected']
    assert dropped / 328 < 0.10 and dropped == round(0.4 * expected_mz)
    result = _refit(tmp_path, events, force=True)
    gate = _gates(result)['schedule']
    assert not gate['passed'] and 'lost coverage: ' in gate['reason']
    assert f'MZ {expected_mz - dropped} of {expected_mz}' in gate['reason']
    assert gate['coverage']['MZ']['found'] == expected_mz - dropped


def test_the_gate_judges_against_the_schedule_it_is_given(clean, tmp_path):
    # a campaign that ran only points 1-200 of the schedule: refused against the full schedule,
    # passed against the schedule it ran (what `refit --schedule FILE` will pass)
    from balance_calib.gates.schedule import schedule_gate
    from balance_calib.refit.pipeline import campaign_points
    from balance_calib.simulation.timeline import select_points

    config = load_balance_config('lmc6522')
    points = campaign_points(clean[0])
    ran = select_points(config.schedule, '1-200')
    part = points.subset(np.isin(points.label, ran.point))
    assert not schedule_gate(config, part, config.schedule).passed
    gate = schedule_gate(config, part, ran)
    assert gate.passed and gate.details['expected'] == len(ran) and gate.details['missing'] == 0
    assert schedule_gate(config, part, None).passed  # no schedule: nothing to compare


def test_no_runtime_warning_reaches_the_user_of_a_refit(clean, tmp_path):
    events = _copy_events(clean[1])
    loads = _load_events(events)
    events[loads[40]].values[2] = -1e300  # a flipped exponent bit in one weight
    bag = write_mcap(events, tmp_path / 'absurd.mcap')
    strict = [
        sys.executable,
        '-W',
        'error',
        '-m',
        'balance_calib.cli',
        'refit',
        '--balance',
        'lmc6522',
    ]
    done = subprocess.run(
        strict + [str(bag), '--out', str(tmp_path / 'out'), '--no-diagnosis'],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2 and done.stderr.count('\n') == 1, done.stderr
    assert 'FZ -1e+300 is beyond 1000x its rated load 9800' in done.stderr
    # and a clean campaign, damaged by 2 %, refits under -W error (a warning would be an error)
    damaged, _ = _without_markers(clean[1], 0.02, seed=4)
    bag = write_mcap(damaged, tmp_path / 'two_percent.mcap')
    done = subprocess.run(
        strict + [str(bag), '--out', str(tmp_path / 'out2')],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0 and done.stderr == '', done.stderr
    assert 'points are missing from the campaign' in done.stdout
