"""balance_daq's pure core (daq/): parameters refused in one line, lines and binary records cut
and parsed, units converted to mV, status, saturation, sequence and device time, the counters and
the /diagnostics levels. Expected numbers are worked by hand from docs/interfaces.md
("Acquisition"); no DDS.
"""

import math
from pathlib import Path
import struct

import numpy as np
import pytest
import yaml

from balance_calib.daq.framing import LineFramer, LineParser, RecordParser
from balance_calib.daq.health import ERROR, Health, OK, WARN
from balance_calib.daq.parameters import daq_settings, PARAMETERS
from balance_calib.daq.samples import Counts, SampleStream
from balance_calib.parameter_table import ParameterError, problems

BRIDGES = ['FXV', 'FYV', 'FZV', 'MXV', 'MYV', 'MZV']
TCP = {'transport': 'tcp', 'device': '127.0.0.1:5000'}
UDP = {'transport': 'udp', 'device': '127.0.0.1:49152'}


def refusal(**values) -> str:
    with pytest.raises(ParameterError) as caught:
        daq_settings(values)
    message = str(caught.value)
    assert '\n' not in message, message
    return message


# --- parameters ----------------------------------------------------------------------------------
def test_the_table_is_consistent_and_its_defaults_are_the_contracts():
    assert problems(PARAMETERS) == []
    settings = daq_settings({})
    assert (settings.transport, settings.device, settings.baud) == (
        'serial',
        '/dev/ttyUSB0',
        115200,
    )
    assert settings.columns == tuple(BRIDGES) and settings.units == 'mV'
    assert settings.saturation == (math.inf,) * 6 and settings.counts_to_mv == (1.0,) * 6
    assert (settings.expected_rate_hz, settings.stale_after_s) == (1000.0, 0.5)
    assert (settings.reconnect_period_s, settings.frame_id) == (1.0, 'balance')
    assert settings.excitation_v == 5.0 and settings.framing == 'line'


@pytest.mark.parametrize(
    'values,named',
    [
        ({'transport': 'can'}, 'parameter transport must be one of serial, tcp, udp'),
        ({'framing': 'json'}, 'parameter framing must be one of line, binary'),
        ({'units': 'mv'}, 'parameter units must be one of mV, V, mV/V, uV/V, counts'),
        ({'columns': BRIDGES[:5]}, 'parameter columns must name each of'),
        ({'columns': BRIDGES + ['FXV']}, 'parameter columns must name each of'),
        ({'columns': BRIDGES + ['seq', 'seq']}, 'parameter columns must name each of'),
        ({'columns': BRIDGES + ['volts']}, "parameter columns: unknown column 'volts'"),
        ({**TCP, 'framing': 'binary', 'record_format': '>6i'}, 'parameter framing binary'),
        ({'framing': 'binary', 'record_format': '>6i'}, 'parameter framing binary'),
        ({**UDP, 'framing': 'binary', 'record_format': '>3Q6z'}, 'parameter record_format'),
        ({**UDP, 'framing': 'binary', 'record_format': ''}, 'parameter record_format'),
        ({**UDP, 'framing': 'binary', 'record_format': '>6s'}, 'parameter record_format'),
        ({**UDP, 'framing': 'binary', 'record_format': '>3I6i'}, 'parameter record_format'),
        ({'counts_to_mv': [1.0, 2.0]}, 'parameter counts_to_mv must hold one value or six'),
        ({'counts_to_mv': [0.0]}, 'parameter counts_to_mv must not be 0'),
        ({'saturation': [math.nan]}, 'parameter saturation must be a list of numbers'),
        ({'saturation': [-1.0]}, 'parameter saturation must be > 0'),
        ({'start_request': '12340002zz'}, 'parameter start_request must be hex bytes'),
        ({'transport': 'tcp', 'device': '/dev/ttyUSB0'}, 'parameter device must be host:port'),
        ({'transport': 'udp', 'device': 'localhost:99999'}, 'parameter device must be host:port'),
        ({'excitation_v': 0.0}, 'parameter excitation_v must be in (0, inf)'),
        ({'baud': 0}, 'parameter baud must be in'),
    ],
)
def test_bad_parameters_are_refused_in_one_line_naming_the_parameter(values, named):
    assert refusal(**values).startswith(named)


def test_the_record_formats_field_count_must_equal_the_columns():
    message = refusal(**UDP, framing='binary', record_format='>3I6i')  # 9 fields, 6 columns
    assert 'holds 9 fields but columns names 6' in message
    rdt = ['seq', '_', 'status'] + BRIDGES
    settings = daq_settings({**UDP, 'framing': 'binary', 'record_format': '>3I6i', 'columns': rdt})
    assert settings.column('seq') == 0 and settings.column('status') == 2
    assert settings.bridge_columns == (3, 4, 5, 6, 7, 8) and settings.address == (
        '127.0.0.1',
        49152,
    )


def test_requests_are_hex_and_per_bridge_lists_take_one_or_six():
    settings = daq_settings(
        {
            'start_request': '1234000200000000',
            'counts_to_mv': [1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
            'saturation': [100.0],
        }
    )
    assert settings.start_request == b'\x12\x34\x00\x02\x00\x00\x00\x00'
    assert settings.counts_to_mv == (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    assert settings.saturation == (100.0,) * 6


# --- lines ---------------------------------------------------------------------------------------
def lines_of(*chunks, partial_first=False):
    framer = LineFramer()
    framer.restart(partial_first)
    lines, overlong = [], 0
    for chunk in chunks:
        more, dropped = framer.feed(chunk)
        lines += more
        overlong += dropped
    return lines, overlong, framer


def test_lines_end_with_lf_or_crlf_and_a_line_may_span_chunks():
    lines, overlong, framer = lines_of(b'1 2\r\n3 ', b'4\n5 6')
    assert lines == [b'1 2\r', b'3 4'] and overlong == 0
    assert framer.lost_partial() is True  # '5 6' was cut
    parsed = LineParser(('FXV', 'FYV')).parse(lines)
    assert parsed.fields.tolist() == [[1.0, 2.0], [3.0, 4.0]] and parsed.malformed == 0


def test_a_serial_ports_first_line_is_dropped_uncounted_a_tcp_streams_is_kept():
    serial, _, _ = lines_of(b'.5,6\n1,2\n', partial_first=True)
    tcp, _, _ = lines_of(b'.5,6\n1,2\n', partial_first=False)
    assert serial == [b'1,2'] and tcp == [b'.5,6', b'1,2']
    # the discarded first line may come in pieces
    pieces, _, _ = lines_of(b'3,4', b'5\n7,8\n', partial_first=True)
    assert pieces == [b'7,8']


def test_a_line_longer_than_the_limit_is_one_malformed_record_and_its_tail_is_dropped():
    lines, overlong, _ = lines_of(b'1,2\n' + b'9' * 3000, b'9' * 3000, b'9,9\n3,4\n')
    assert lines == [b'1,2', b'3,4'] and overlong == 1
    # however many chunks it spans, and whether or not it ends before the device goes away
    endless = [b'9' * 3000] * 7
    lines, overlong, framer = lines_of(*endless, b'9\n5,6\n')
    assert lines == [b'5,6'] and overlong == 1
    lines, overlong, framer = lines_of(*endless)
    assert lines == [] and overlong == 1 and framer.lost_partial() is False


@pytest.mark.parametrize(
    'line,fields',
    [
        (b'1,2,3', [1, 2, 3]),
        (b'1;2;3', [1, 2, 3]),
        (b'1 2\t\t3', [1, 2, 3]),
        (b'  1,  2 ,3  ', [1, 2, 3]),  # spaces around a comma belong to it
        (b'-1.5e-3;+2;.25', [-0.0015, 2, 0.25]),
    ],
)
def test_separators_are_a_comma_a_semicolon_or_a_run_of_blanks(line, fields):
    parsed = LineParser(('FXV', 'FYV', 'FZV')).parse([line])
    assert parsed.fields.tolist() == [fields] and parsed.malformed == 0


@pytest.mark.parametrize(
    'line',
    [
        b'1,,2',  # an empty field
        b'1,2,',  # a trailing one
        b'1,2',  # short
        b'1,2,3,4',  # long
        b'1,2,x',  # not a number
        b'1,2,0x10',
        b'1,\xff\xfe,3',  # not UTF-8
        b'1,2,\xd9\xa3',  # a digit, but not ASCII
        bytes(range(1, 40)),  # random bytes
    ],
)
def test_malformed_lines_are_counted_and_never_parsed(line):
    parsed = LineParser(('FXV', 'FYV', 'FZV')).parse([line, b'7 8 9'])
    assert parsed.fields.tolist() == [[7, 8, 9]] and parsed.malformed == 1


def test_without_a_prefix_blank_lines_are_not_records():
    parsed = LineParser(('FXV', 'FYV')).parse([b'', b'  \r', b'1 2'])
    assert parsed.fields.tolist() == [[1, 2]] and parsed.malformed == 0


def test_with_a_prefix_other_lines_are_skipped_uncounted_and_returned_to_be_logged():
    parser = LineParser(('FXV', 'FYV', '_'), line_prefix='D')
    parsed = parser.parse(
        [b'HX711 ready', b'D,1,2,t0', b'DEBUG 3 4 5', b'D 5 6 anything', b'\xff\xfe', b'D,1,2']
    )
    assert parsed.fields[:, :2].tolist() == [[1, 2], [5, 6]]
    assert np.isnan(parsed.fields[:, 2]).all()  # `_` is ignored, whatever it holds
    assert parsed.malformed == 1  # 'D,1,2' has the prefix but two fields where three are due
    assert parsed.non_data == ['HX711 ready', 'DEBUG 3 4 5', '\ufffd\ufffd']


def test_nan_and_inf_text_parses_and_is_left_to_the_finite_check():
    parsed = LineParser(('FXV', 'FYV')).parse([b'nan 1', b'1 inf', b'-Infinity 2'])
    assert parsed.malformed == 0 and len(parsed.fields) == 3
    assert (~np.isfinite(parsed.fields)).any(axis=1).all()


# --- binary records ------------------------------------------------------------------------------
RDT_COLUMNS = ('seq', '_', 'status') + tuple(BRIDGES)


def test_big_endian_rdt_records_several_to_a_datagram():
    # by hand: rdt_sequence 1, ft_sequence 7, status 0, counts 1, -1, 256, -256, 65536, 0
    one = bytes.fromhex('00000001000000070000000000000001ffffffff00000100ffffff000001000000000000')
    two = bytes.fromhex('000000020000000880000000' + '00000000' * 5 + '7fffffff')
    three = bytes.fromhex('000000030000000900000000' + '00000002' * 6)
    parser = RecordParser('>3I6i', RDT_COLUMNS)
    parsed = parser.parse([one + two + three])
    assert parsed.malformed == 0
    assert parsed.fields[:, [0, 2, 3, 4, 5, 6, 7, 8]].tolist() == [
        [1, 0, 1, -1, 256, -256, 65536, 0],
        [2, 2**31, 0, 0, 0, 0, 0, 2**31 - 1],
        [3, 0, 2, 2, 2, 2, 2, 2],
    ]
    assert np.isnan(parsed.fields[:, 1]).all()  # ft_sequence is `_`


def test_a_datagram_that_is_not_whole_records_is_one_malformed_record():
    parser = RecordParser('<6h', tuple(BRIDGES))
    parsed = parser.parse([bytes(13), b'', struct.pack('<6h', 1, 2, 3, 4, 5, -6)])
    assert parsed.malformed == 2 and parsed.fields.tolist() == [[1, 2, 3, 4, 5, -6]]


# --- samples -------------------------------------------------------------------------------------
def stream(**values):
    return SampleStream(daq_settings(values))


def rows(*records):
    return np.array(records, dtype=float)


@pytest.mark.parametrize(
    'units,extra,field,mv',
    [
        ('mV', {}, 2.5, 2.5),
        ('V', {}, 0.0025, 2.5),
        ('mV/V', {'excitation_v': 10.0}, 2.0, 20.0),  # 2 mV/V x 10 V
        ('uV/V', {'excitation_v': 10.0}, 500.0, 5.0),  # 500 uV/V x 10 V = 5000 uV
        ('counts', {'counts_to_mv': [0.001]}, 2500.0, 2.5),
    ],
)
def test_units_become_mv(units, extra, field, mv):
    out = stream(units=units, **extra).take(rows([field] * 6), 1_000)
    assert out.bridges_mv[0].tolist() == pytest.approx([mv] * 6, rel=1e-12)


def test_counts_take_one_scale_per_bridge_and_a_samples_excitation_replaces_the_nominal():
    scales = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    out = stream(units='counts', counts_to_mv=scales).take(rows([10, 10, 10, 10, 10, 10]), 0)
    assert out.bridges_mv.tolist() == [[10, 20, 30, 40, 50, 60]]
    ratiometric = stream(units='mV/V', excitation_v=5.0, columns=BRIDGES + ['excitation'])
    out = ratiometric.take(rows([1, 1, 1, 1, 1, 2, 9.5], [1, 1, 1, 1, 1, 1, 0.0]), 0)
    assert out.bridges_mv.tolist() == [[9.5, 9.5, 9.5, 9.5, 9.5, 19.0]]
    assert ratiometric.counts.records_malformed == 1  # an excitation of 0 V is no measurement


def test_a_sample_is_published_only_when_whole_finite_unflagged_and_unsaturated():
    daq = stream(columns=BRIDGES + ['status'], saturation=[5.0, 5.0, 5.0, 5.0, 5.0, 100.0])
    out = daq.take(
        rows(
            [1, 2, 3, 4, 4.99, 99, 0],  # published
            [1, 2, math.nan, 4, 4, 4, 0],  # malformed
            [1, 2, 3, 4, 4, math.inf, 0],  # malformed although inf reaches any saturation
            [1, 2, 3, 4, 4, 4, 8],  # invalid: status 8
            [1, 2, 3, -5.0, 4, 4, 0],  # saturated: |MXV| reaches 5
            [1, 2, 3, 4, 4, 100.0, 3],  # flagged and saturated: counted invalid only
            [0, 0, 0, 0, 0, 0, math.nan],  # a status that is not a number: malformed
        ),
        1_000,
    )
    assert out.bridges_mv.tolist() == [[1, 2, 3, 4, 4.99, 99]]
    counts = daq.counts
    assert (counts.samples_published, counts.records_malformed) == (1, 3)
    assert (counts.samples_invalid, counts.samples_saturated) == (2, 1)


def test_saturation_is_in_the_units_of_the_fields():
    daq = stream(units='counts', counts_to_mv=[0.001], saturation=[8388607.0])
    out = daq.take(rows([8388606] * 6, [8388607] + [0] * 5, [0] * 5 + [-8388608]), 0)
    assert out.bridges_mv.tolist() == [[8388.606] * 6]
    assert daq.counts.samples_saturated == 2


def test_sequence_gaps_duplicates_late_samples_and_restarts():
    daq = stream(columns=['seq'] + BRIDGES)
    seq = [10, 11, 14, 14, 12, 15, 9000, 100, 101]
    # 14 skips 12 and 13: two missing; 14 again: a duplicate; 12 (back by 2): late; 15 follows
    # 14; 9000 skips 8984; 100 (back by 8900 >= 1000) starts the count afresh; 101 follows it
    out = daq.take(rows(*[[s, s, 0, 0, 0, 0, 0] for s in seq]), 0)
    assert out.bridges_mv[:, 0].tolist() == [10, 11, 14, 15, 9000, 100, 101]
    assert (daq.counts.samples_missing, daq.counts.samples_duplicate) == (2 + 8984, 2)


def test_the_sequence_wraps_at_two_to_the_32_and_spans_chunks():
    daq = stream(columns=['seq'] + BRIDGES)
    daq.take(rows([2**32 - 2] + [0] * 6, [2**32 - 1] + [0] * 6), 0)
    out = daq.take(rows([0] + [1] * 6, [2] + [2] * 6), 0)  # 0 follows 2**32 - 1; 1 is missing
    assert out.bridges_mv[:, 0].tolist() == [1, 2]
    assert (daq.counts.samples_missing, daq.counts.samples_duplicate) == (1, 0)
    bad = daq.take(rows([-1] + [0] * 6, [1.5] + [0] * 6, [2**32] + [0] * 6), 0)
    assert len(bad) == 0 and daq.counts.records_malformed == 3


def test_invalid_and_saturated_records_move_the_sequence_on_a_restart_starts_it_afresh():
    daq = stream(columns=['seq', 'status'] + BRIDGES, saturation=[10.0])
    daq.take(
        rows([1, 0, 1, 1, 1, 1, 1, 1], [2, 4, 1, 1, 1, 1, 1, 1], [3, 0, 10, 1, 1, 1, 1, 1]), 0
    )
    out = daq.take(rows([4, 0, 2, 2, 2, 2, 2, 2]), 0)
    assert len(out) == 1 and daq.counts.samples_missing == 0
    assert (daq.counts.samples_invalid, daq.counts.samples_saturated) == (1, 1)
    daq.restart()  # a reconnect: the device may count from anywhere
    assert len(daq.take(rows([70, 0, 1, 1, 1, 1, 1, 1]), 0)) == 1
    assert (daq.counts.samples_missing, daq.counts.samples_duplicate) == (0, 0)


def test_without_device_time_stamps_are_the_arrival_strictly_increasing():
    daq = stream()
    first = daq.take(rows([1] * 6, [2] * 6, [3] * 6), 5_000)
    assert first.stamps_ns.tolist() == [5_000, 5_001, 5_002]
    assert daq.take(rows([4] * 6), 5_001).stamps_ns.tolist() == [5_003]
    assert daq.take(rows([5] * 6), 9_000).stamps_ns.tolist() == [9_000]


def test_device_time_is_carried_alike_one_record_a_read_or_all_in_one_chunk():
    # device times with a step back and a step forward over 1 s (two jumps), all arriving at once
    # or one per read at the same host time: the one-record path gives the chunk's stamps
    times = [5.0, 5.001, 5.002, 4.0, 4.001, 6.5, 6.501]
    records = rows(*[[0] * 6 + [t] for t in times])
    whole = stream(columns=BRIDGES + ['time'])
    expected = whole.take(records, 7_000_000_000).stamps_ns.tolist()
    single = stream(columns=BRIDGES + ['time'])
    stamps = [single.take(records[i : i + 1], 7_000_000_000).stamps_ns[0] for i in range(7)]
    assert stamps == expected and single.counts.time_jumps == whole.counts.time_jumps == 2
    ms = 1_000_000  # by hand: offset fixed at 5.0 s, again at 4.0 s and at 6.5 s
    assert expected[:3] == [7_000 * ms, 7_001 * ms, 7_002 * ms]
    assert expected[3:] == [7_002 * ms + 1, 7_002 * ms + 2, 7_002 * ms + 3, 7_002 * ms + 4]


def test_device_time_keeps_its_spacing_on_the_host_clock_and_is_refixed_after_a_jump():
    daq = stream(columns=BRIDGES + ['time'])
    s = 1_000_000_000
    # offset fixed at the first sample: host 50 s when the device said 10 s
    out = daq.take(rows([0] * 6 + [10.0], [0] * 6 + [10.001], [0] * 6 + [10.002]), 50 * s)
    assert out.stamps_ns.tolist() == [50 * s, 50 * s + 1_000_000, 50 * s + 2_000_000]
    # a later chunk arrives late: the device's spacing holds, not the arrival time
    out = daq.take(rows([0] * 6 + [10.003]), 50 * s + 90_000_000)
    assert out.stamps_ns.tolist() == [50 * s + 3_000_000]
    # forward by 1.5 s (> 1 s): re-fixed at this chunk's arrival
    out = daq.take(rows([0] * 6 + [11.503], [0] * 6 + [11.504]), 52 * s)
    assert out.stamps_ns.tolist() == [52 * s, 52 * s + 1_000_000]
    # back by 0.5 s: re-fixed too
    out = daq.take(rows([0] * 6 + [11.004]), 53 * s)
    assert out.stamps_ns.tolist() == [53 * s]
    # forward by exactly 1 s is no jump
    out = daq.take(rows([0] * 6 + [12.004]), 60 * s)
    assert out.stamps_ns.tolist() == [54 * s]
    assert daq.counts.time_jumps == 2
    daq.restart()  # after a reconnect the offset is fixed again
    out = daq.take(rows([0] * 6 + [12.005]), 70 * s)
    assert out.stamps_ns.tolist() == [70 * s] and daq.counts.time_jumps == 2


def test_temperature_goes_with_the_published_samples_only():
    daq = stream(columns=BRIDGES + ['temperature', 'status'])
    out = daq.take(rows([1] * 6 + [21.5, 0], [1] * 6 + [22.0, 1], [2] * 6 + [23.0, 0]), 0)
    assert out.temperature_c.tolist() == [21.5, 23.0]
    assert stream().take(rows([1] * 6), 0).temperature_c is None


# --- /diagnostics --------------------------------------------------------------------------------
def health():
    return Health('127.0.0.1:5000', expected_rate_hz=100.0, stale_after_s=0.5, start_s=0.0)


def test_the_status_carries_the_contracts_keys_and_name():
    status = health().status(Counts(samples_published=100), True, 1.0, 0.99)
    assert status.name == 'balance_daq: 127.0.0.1:5000'
    assert [key for key, _ in status.values] == [
        'rate_hz',
        'samples_published',
        'records_malformed',
        'samples_invalid',
        'samples_saturated',
        'samples_missing',
        'samples_duplicate',
        'reconnects',
        'last_sample_age_s',
        'connected',
    ]
    values = dict(status.values)
    assert (values['rate_hz'], values['samples_published'], values['connected']) == (
        '100.0',
        '100',
        'true',
    )
    assert values['last_sample_age_s'] == '0.010' and status.level == OK


def test_levels_warn_for_the_rate_and_drops_error_for_disconnected_stale_and_saturated():
    checker = health()
    # 100 Hz expected: 85 samples in a second are within 20 %; 79 are not
    assert checker.status(Counts(samples_published=85), True, 1.0, 1.0).level == OK
    assert checker.status(Counts(samples_published=85 + 79), True, 2.0, 2.0).level == WARN
    total = 164 + 100
    dropped = Counts(samples_published=total, samples_duplicate=1)
    assert checker.status(dropped, True, 3.0, 3.0).level == WARN
    total += 100
    again = Counts(samples_published=total, samples_duplicate=1)  # no new drop: OK again
    assert checker.status(again, True, 4.0, 4.0).level == OK
    total += 100
    saturated = Counts(samples_published=total, samples_duplicate=1, samples_saturated=1)
    assert checker.status(saturated, True, 5.0, 5.0).level == ERROR
    total += 100
    saturated = Counts(samples_published=total, samples_duplicate=1, samples_saturated=1)
    assert checker.status(saturated, False, 6.0, 6.0).level == ERROR
    stale = checker.status(saturated, True, 7.0, 6.4)
    assert stale.level == ERROR and 'stale' in stale.message
    assert dict(stale.values)['last_sample_age_s'] == '0.600'


def test_before_any_sample_the_age_counts_from_the_start():
    status = health().status(Counts(), True, 2.0, None)
    assert status.level == ERROR and dict(status.values)['last_sample_age_s'] == '2.000'


# --- presets -------------------------------------------------------------------------------------
PRESETS = sorted((Path(__file__).resolve().parents[2] / 'config' / 'daq').glob('*.yaml'))


def test_the_contracts_three_presets_are_shipped():
    assert [p.name for p in PRESETS] == ['netft_rdt.yaml', 'serial_counts.yaml', 'tcp_mvv.yaml']


@pytest.mark.parametrize('preset', PRESETS, ids=lambda p: p.stem)
def test_each_preset_is_a_params_file_balance_daq_accepts_and_says_what_to_edit(preset):
    text = preset.read_text()
    values = yaml.safe_load(text)['balance_daq']['ros__parameters']
    settings = daq_settings(values)
    assert set(values) <= set(PARAMETERS)
    assert 'What to edit' in text and 'Who sends this' in text
    for knob in (
        'expected_rate_hz',
        'counts_to_mv' if settings.units == 'counts' else 'excitation_v',
    ):
        assert f'#   {knob}' in text, knob
    assert 'saturation' in text


def test_the_rdt_preset_is_atis_request_and_record():
    values = yaml.safe_load(PRESETS[0].read_text())['balance_daq']['ros__parameters']
    settings = daq_settings(values)
    assert settings.start_request == struct.pack('>HHI', 0x1234, 2, 0)
    assert settings.stop_request == struct.pack('>HHI', 0x1234, 0, 0)
    assert struct.calcsize(settings.record_format) == 36 and settings.address[1] == 49152
    assert settings.columns[:3] == ('seq', '_', 'status')


def test_the_plain_chunk_shortcut_gives_what_the_record_by_record_check_gives():
    """SampleStream._plain passes a chunk whole; with it refused, every chunk goes through
    _checked: both must publish and count the same, chunk after chunk (random streams with
    every kind of record, cut into random chunks).
    """
    rng = np.random.default_rng(5)
    columns = ['seq', 'status'] + BRIDGES + ['time', 'excitation']
    for trial in range(30):
        n = 200
        seq = np.cumsum(rng.choice([1, 1, 1, 1, 0, 2, -3, -5000], n)) % 2**32 + 7000
        records = np.column_stack(
            [
                seq,
                rng.choice([0, 0, 0, 0, 0, 0, 1], n),
                rng.normal(0, 4, (n, 6)),
                np.cumsum(rng.choice([1e-3, 1e-3, 1e-3, 2.0, -0.5], n)),
                rng.choice([5.0, 5.0, 5.0, 5.0, 0.0], n),
            ]
        )
        records[rng.random((n, len(columns))) < 0.01] = np.nan
        cuts = np.sort(rng.choice(np.arange(1, n), 60, replace=False))
        settings = {'columns': columns, 'units': 'mV/V', 'saturation': [9.0]}
        shortcut, checked = stream(**settings), stream(**settings)
        checked._plain = lambda fields: False
        plain = shortcut._plain
        passed = []
        shortcut._plain = lambda fields: passed.append(plain(fields)) or passed[-1]
        for k, chunk in enumerate(np.split(records, cuts)):
            arrival = 10**9 * (k + 1)
            one, other = shortcut.take(chunk, arrival), checked.take(chunk, arrival)
            assert one.stamps_ns.tolist() == other.stamps_ns.tolist()
            assert one.bridges_mv.tolist() == other.bridges_mv.tolist()
        assert shortcut.counts == checked.counts, trial
        assert shortcut.counts.samples_published > 20 and any(passed)  # both ways were taken


def test_a_device_time_jump_is_said_in_the_message_at_no_level_of_its_own():
    checker = health()
    status = checker.status(Counts(samples_published=100, time_jumps=1), True, 1.0, 1.0)
    assert status.level == OK
    assert status.message == 'ok; device time jumped 1 time(s): stamps re-fixed'
    status = checker.status(Counts(samples_published=200, time_jumps=1), True, 2.0, 2.0)
    assert status.message == 'ok'
