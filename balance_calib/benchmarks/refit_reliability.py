"""Refit reliability: damaged and mislabelled campaigns through the refit, counted.

    python -m balance_calib.benchmarks.refit_reliability [--mutants 416] [--cli 8] [--memory]

Small simulated campaigns (LMC6522 and B660H, Appendix A/B schedules, a few samples a point) are
written as MCAP bags, then damaged or mislabelled in deterministic ways (seeded): truncations,
flipped bytes in files with and without chunk CRCs, dropped / reordered / duplicated messages,
loads in kgf or lbf, outputs in V, a clipped bridge, one wrong weight, a wrong --balance, a
negative or reversed calibration body, time jumps forward and back, zero stamps, sessions split by
pauses, tiny and foreign files.
Each goes through the refit pipeline (in-process; a few through the `balance-calib refit` CLI) and
is classed:

    refused      a RefitError (CLI: exit 2 with one line on stderr naming a file)
    accepted     written; then the calibration is compared with the simulation's truth: the loads
                 it gives for the true outputs at the schedule's points must be within
                 TOLERANCE_PCT_FS (RMS per component) of the true loads, else it is `silent_wrong`
    traceback    any other exception (CLI: anything else on stderr or another exit status)
    hang         no answer within the per-mutant time limit (CLI only: in-process runs are bounded
                 by the campaign's size)
    unnamed      refused, but the one line names none of the files given

With --memory, the peak resident memory of full refits (diagnosis on) of one campaign unsplit and
split in two sessions 1 h and 16 h apart is measured, each in its own process. The fuzz test
(test/refit/test_refit_fuzz.py) runs a few hundred of the same mutants.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import json
from pathlib import Path
import subprocess
import sys
import tempfile
import time
from typing import Callable, Iterator

import numpy as np

TOLERANCE_PCT_FS = 0.1  # RMS load error an accepted calibration may have, % FS per component
START_NS = 1_700_000_000 * 10**9
RAW, LOAD, GRAVITY, TEMPERATURE = (
    '/balance/raw',
    '/calibration/applied_load',
    '/calibration/gravity',
    '/balance/temperature',
)
TYPES = {
    RAW: 'geometry_msgs/msg/WrenchStamped',
    LOAD: 'geometry_msgs/msg/WrenchStamped',
    GRAVITY: 'geometry_msgs/msg/Vector3Stamped',
    TEMPERATURE: 'sensor_msgs/msg/Temperature',
}
KGF_N = 9.80665
LBF_N = 4.4482216152605


@dataclass
class Event:
    """One message before serialisation: receive time, topic, header stamp and its numbers."""

    log_ns: int
    order: int
    topic: str
    stamp_ns: int
    values: np.ndarray


@dataclass(frozen=True)
class Clean:
    """One simulated campaign and its messages."""

    balance: str
    campaign: object
    events: tuple[Event, ...]


def small_campaign(balance: str = 'lmc6522', seed: int = 0, samples_per_point: int = 4):
    from ..config import load_balance_config
    from ..simulation.balance_sim import simulate_campaign, SimulationSettings, table17_noise

    config = load_balance_config(balance)
    settings = SimulationSettings(
        samples_per_point=samples_per_point,
        transition_samples=1,
        point_duration_s=1.0,
        transition_s=0.5,
        noise_sigma_pct_fs=table17_noise(config),
        seed=seed,
    )
    return simulate_campaign(config, settings=settings)


def campaign_events(campaign, start_ns: int = START_NS) -> list[Event]:
    """The messages bridge_publisher sends in calibration mode (simulation/campaign_bag.py's)."""
    events = []
    previous_orientation = None
    nan6 = np.full(6, np.nan)
    for p in range(len(campaign.point)):
        previous_end = campaign.end_s[p - 1] if p > 0 else campaign.start_s[0] - 1.0
        transition_ns = start_ns + int(round(previous_end * 1e9)) + 1
        if campaign.orientation[p] != previous_orientation:
            events.append(
                Event(
                    transition_ns,
                    0,
                    GRAVITY,
                    transition_ns,
                    np.asarray(campaign.gravity[p], float),
                )
            )
            previous_orientation = campaign.orientation[p]
        events.append(Event(transition_ns, 1, LOAD, transition_ns, nan6.copy()))
        settled_ns = start_ns + int(round(campaign.start_s[p] * 1e9))
        events.append(
            Event(settled_ns, 1, LOAD, settled_ns, np.asarray(campaign.applied_loads[p], float))
        )
    for i in range(len(campaign.times_s)):
        ns = start_ns + int(round(campaign.times_s[i] * 1e9))
        events.append(Event(ns, 2, RAW, ns, np.asarray(campaign.raw_mv[i], float)))
        if i % 4 == 0:
            events.append(Event(ns, 3, TEMPERATURE, ns, np.array([campaign.temperature_c[i]])))
    events.sort(key=lambda e: (e.log_ns, e.order))
    return events


_PAYLOADS: dict = {}


def _payload(event: Event, frame: str) -> bytes:
    key = (event.topic, event.stamp_ns, frame, event.values.tobytes())
    cached = _PAYLOADS.get(key)
    if cached is None:
        if len(_PAYLOADS) > 200_000:
            _PAYLOADS.clear()
        cached = _PAYLOADS[key] = _serialize(event, frame)
    return cached


def _serialize(event: Event, frame: str) -> bytes:
    from ..bags.messages import temperature_cdr, vector_cdr, wrench_cdr

    if event.topic == GRAVITY:
        return vector_cdr(event.stamp_ns, frame, event.values)
    if event.topic == TEMPERATURE:
        return temperature_cdr(event.stamp_ns, frame, float(event.values[0]))
    return wrench_cdr(event.stamp_ns, frame, event.values)


def write_mcap(
    events,
    path: Path,
    *,
    frame: str = 'LMC6522',
    crcs: bool = True,
    chunk_size: int = 16 * 1024,
    compression: str = 'zstd',
) -> Path:
    """A bare .mcap file (ros2 profile) with or without chunk and summary CRCs, small chunks."""
    from mcap.writer import CompressionType, Writer
    from rosbags.typesys import get_typestore, Stores

    store = get_typestore(Stores.ROS2_JAZZY)
    kinds = {
        'zstd': CompressionType.ZSTD,
        'lz4': CompressionType.LZ4,
        'none': CompressionType.NONE,
    }
    with open(path, 'wb') as stream:
        writer = Writer(
            stream, chunk_size=chunk_size, compression=kinds[compression], enable_crcs=crcs
        )
        writer.start(profile='ros2', library='refit_reliability')
        schemas, channels, sequence = {}, {}, {}
        for topic, msgtype in TYPES.items():
            if msgtype not in schemas:
                schemas[msgtype] = writer.register_schema(
                    name=msgtype,
                    encoding='ros2msg',
                    data=store.generate_msgdef(msgtype, ros_version=2)[0].encode(),
                )
            channels[topic] = writer.register_channel(
                topic=topic, message_encoding='cdr', schema_id=schemas[msgtype], metadata={}
            )
            sequence[topic] = 0
        for event in events:
            writer.add_message(
                channel_id=channels[event.topic],
                log_time=int(event.log_ns),
                data=_payload(event, frame),
                publish_time=int(event.log_ns),
                sequence=sequence[event.topic],
            )
            sequence[event.topic] += 1
        writer.finish()
    return path


# -- mutants --------------------------------------------------------------------------------------


@dataclass
class Mutant:
    name: str
    kind: str  # family, for the counts
    paths: list[Path]
    balance: str  # --balance given
    truth_balance: str  # the balance that made the data
    campaign: object
    config_path: Path | None = None
    expect: str = 'either'  # 'refuse' when no correct calibration can come out


def _copy_events(events) -> list[Event]:
    return [Event(e.log_ns, e.order, e.topic, e.stamp_ns, e.values.copy()) for e in events]


def _flip(data: bytes, rng, *, start: int, end: int, count: int) -> bytes:
    damaged = bytearray(data)
    for at in rng.integers(start, max(end, start + 1), size=count):
        damaged[int(at)] ^= int(rng.integers(1, 256))
    return bytes(damaged)


def mutants(clean: Clean, workdir: Path, seed: int, count: int) -> Iterator[Mutant]:
    """`count` deterministic mutants of one clean campaign (files written into workdir)."""
    rng = np.random.default_rng(seed)
    campaign, balance = clean.campaign, clean.balance
    frame = campaign.balance
    other = 'b660h' if balance == 'lmc6522' else 'lmc6522'
    loads_index = [
        i for i, e in enumerate(clean.events) if e.topic == LOAD and not np.all(np.isnan(e.values))
    ]
    raw_index = [i for i, e in enumerate(clean.events) if e.topic == RAW]
    base = workdir / f'{balance}-{seed}-clean.mcap'
    write_mcap(clean.events, base, frame=frame)
    base_bytes = base.read_bytes()
    nocrc = workdir / f'{balance}-{seed}-nocrc.mcap'
    write_mcap(clean.events, nocrc, frame=frame, crcs=False)
    nocrc_bytes = nocrc.read_bytes()
    kinds = [
        'clean',
        'truncate',
        'flip_crc',
        'flip_nocrc',
        'drop_raw',
        'drop_marker',
        'drop_gravity',
        'swap_marker_stamps',
        'reorder_raw',
        'duplicate',
        'kgf',
        'lbf',
        'volts',
        'clip',
        'wrong_weight',
        'wrong_balance',
        'negative_body',
        'reversed_gravity',
        'time_jump',
        'split_pause',
        'tiny',
        'flip_summary',
        'raw_clock_jump',
        'lz4_flip_nocrc',
        'clock_back',
        'zero_stamps',
    ]
    for n in range(count):
        kind = kinds[n % len(kinds)]
        name = f'{balance}-s{seed}-{n:03d}-{kind}'
        path = workdir / f'{name}.mcap'
        expect = 'either'
        events = None
        config_path = None
        paths = [path]
        given_balance = balance
        if kind == 'clean':
            events = clean.events
        elif kind == 'truncate':
            path.write_bytes(base_bytes[: int(rng.integers(9, len(base_bytes) - 1))])
            expect = 'refuse'
        elif kind in ('flip_crc', 'flip_nocrc'):
            data = base_bytes if kind == 'flip_crc' else nocrc_bytes
            path.write_bytes(
                _flip(data, rng, start=64, end=len(data) - 64, count=int(rng.integers(1, 20)))
            )
        elif kind == 'lz4_flip_nocrc':
            write_mcap(clean.events, path, frame=frame, crcs=False, compression='lz4')
            data = path.read_bytes()
            path.write_bytes(
                _flip(data, rng, start=64, end=len(data) - 64, count=int(rng.integers(1, 5)))
            )
        elif kind == 'flip_summary':
            data = base_bytes if rng.random() < 0.5 else nocrc_bytes
            path.write_bytes(
                _flip(
                    data,
                    rng,
                    start=int(len(data) * 0.9),
                    end=len(data) - 8,
                    count=int(rng.integers(1, 4)),
                )
            )
        elif kind == 'tiny':
            path.write_bytes(
                [b'', b'\x89MCAP0\r\n', b'not a bag at all', base_bytes[:8]][
                    int(rng.integers(0, 4))
                ]
            )
            expect = 'refuse'
        else:
            events = _copy_events(clean.events)
            if kind == 'drop_raw':
                drop = set(
                    rng.choice(raw_index, size=len(raw_index) // 10, replace=False).tolist()
                )
                events = [e for i, e in enumerate(events) if i not in drop]
            elif kind == 'drop_marker':
                drop = int(rng.choice(loads_index))
                events = [e for i, e in enumerate(events) if i != drop]
            elif kind == 'drop_gravity':
                gravity = [i for i, e in enumerate(events) if e.topic == GRAVITY][1:]
                drop = int(rng.choice(gravity))
                events = [e for i, e in enumerate(events) if i != drop]
            elif kind == 'swap_marker_stamps':
                a = int(rng.integers(0, len(loads_index) - 8))
                i, j = loads_index[a], loads_index[a + int(rng.integers(1, 8))]
                events[i].stamp_ns, events[j].stamp_ns = events[j].stamp_ns, events[i].stamp_ns
            elif kind == 'reorder_raw':
                chosen = rng.choice(raw_index, size=len(raw_index) // 5, replace=False)
                for i in chosen:
                    events[i].log_ns += int(rng.integers(-300, 300)) * 10**6
                events.sort(key=lambda e: (e.log_ns, e.order))
            elif kind == 'duplicate':
                chosen = set(
                    rng.choice(len(events), size=len(events) // 10, replace=False).tolist()
                )
                events = [
                    x for i, e in enumerate(events) for x in ((e, e) if i in chosen else (e,))
                ]
            elif kind in ('kgf', 'lbf'):
                for i in loads_index:
                    events[i].values = events[i].values / (KGF_N if kind == 'kgf' else LBF_N)
                expect = 'refuse'
            elif kind == 'volts':
                for i in raw_index:
                    events[i].values = events[i].values / 1000.0
                expect = 'refuse'
            elif kind == 'clip':
                k = int(rng.integers(0, 6))
                column = np.array([events[i].values[k] for i in raw_index])
                limit = float(np.quantile(np.abs(column), 0.97))
                for i in raw_index:
                    events[i].values[k] = np.clip(events[i].values[k], -limit, limit)
            elif kind == 'wrong_weight':
                i = int(
                    rng.choice([i for i in loads_index if np.max(np.abs(events[i].values)) > 0])
                )
                k = int(np.argmax(np.abs(events[i].values) / _capacity(balance)))
                events[i].values[k] *= float(rng.choice([0.9, 1.1, 0.5, 2.0]))
            elif kind == 'wrong_balance':
                given_balance = other
                expect = 'refuse'
            elif kind == 'negative_body':
                config_path = _config_with_body(
                    balance, workdir / f'{name}.yaml', -float(rng.uniform(100, 700))
                )
                given_balance = str(config_path)
                expect = 'refuse'
            elif kind == 'reversed_gravity':
                for e in events:
                    if e.topic == GRAVITY:
                        e.values = -e.values
            elif kind == 'time_jump':
                at = int(rng.integers(len(events) // 4, 3 * len(events) // 4))
                jump = int(float(rng.choice([1e3, 1e5, 1e6])) * 1e9)
                for e in events[at:]:
                    e.log_ns += jump
                    e.stamp_ns += jump
            elif kind == 'raw_clock_jump':
                at = int(rng.integers(len(raw_index) // 4, 3 * len(raw_index) // 4))
                for i in raw_index[at : at + 50]:
                    events[i].stamp_ns += int(1e6 * 1e9)
            elif kind == 'clock_back':
                # the publisher's clock steps back (NTP): every later stamp 5-60 s earlier
                at = int(rng.integers(len(events) // 4, 3 * len(events) // 4))
                step = int(float(rng.uniform(5, 60)) * 1e9)
                for e in events[at:]:
                    e.stamp_ns -= step
            elif kind == 'zero_stamps':
                # some messages stamped 0 (an unset header)
                chosen = rng.choice(len(events), size=int(rng.integers(1, 20)), replace=False)
                for i in chosen:
                    events[int(i)].stamp_ns = 0
            elif kind == 'split_pause':
                at = loads_index[
                    int(rng.integers(len(loads_index) // 4, 3 * len(loads_index) // 4))
                ]
                pause = int(float(rng.choice([600, 3600, 16 * 3600])) * 1e9)
                later = [
                    Event(e.log_ns + pause, e.order, e.topic, e.stamp_ns + pause, e.values)
                    for e in events[at:]
                ]
                # the second session starts by saying where gravity points, as bridge_publisher
                # does
                last_gravity = [e for e in events[:at] if e.topic == GRAVITY][-1]
                later.insert(
                    0,
                    Event(
                        later[0].log_ns - 1, 0, GRAVITY, later[0].stamp_ns - 1, last_gravity.values
                    ),
                )
                second = workdir / f'{name}-b.mcap'
                write_mcap(later, second, frame=frame)
                events = events[:at]
                paths = [path, second]
        if events is not None:
            write_mcap(events, path, frame=frame)
        yield Mutant(name, kind, paths, given_balance, balance, campaign, config_path, expect)


def _capacity(balance: str) -> np.ndarray:
    from ..config import load_balance_config

    return load_balance_config(balance).capacity


def _config_with_body(balance: str, path: Path, weight_n: float) -> Path:
    import yaml

    from ..config import resolve_config_path

    data = yaml.safe_load(resolve_config_path(balance).read_text())
    data['calibration_body']['weight_n'] = weight_n
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


# -- judging --------------------------------------------------------------------------------------


def calibration_error_pct_fs(calibration, mutant: Mutant) -> np.ndarray:
    """RMS over the schedule's points of (calibrated - true) load for the true outputs, % FS."""
    from ..config import load_balance_config
    from ..model.inverse import outputs_for_loads

    truth_config = load_balance_config(mutant.truth_balance)
    truth = truth_config.matrices['cubic'].without_constant()
    outputs = outputs_for_loads(truth, mutant.campaign.true_loads)
    fitted = calibration.model(calibration.base_model).without_constant()
    error = (fitted.loads(outputs) - truth.loads(outputs)) / truth_config.capacity * 100.0
    return np.sqrt(np.mean(error**2, axis=0))


def _names_a_file(text: str, mutant: Mutant) -> bool:
    names = [p.name for p in mutant.paths] + (
        [mutant.config_path.name] if mutant.config_path else []
    )
    return any(name in text for name in names)


def judge_in_process(mutant: Mutant, out_dir: Path) -> tuple[str, str]:
    """(verdict, detail) for one mutant through run_refit in this process."""
    from ..calibrate.from_bags import RefitSettings, run_refit
    from ..refit.errors import RefitError

    try:
        result = run_refit(
            mutant.paths, mutant.balance, out_dir, RefitSettings(diagnose=False, plots=False)
        )
    except RefitError as error:
        text = str(error)
        if '\n' in text or not text:
            return 'traceback', f'error not one line: {text!r}'
        return ('refused' if _names_a_file(text, mutant) else 'unnamed'), text
    except Exception as error:  # what the fuzz exists to find
        import traceback

        return 'traceback', ''.join(traceback.format_exception_only(type(error), error)).strip()
    error = calibration_error_pct_fs(result.calibration, mutant)
    if np.all(error < TOLERANCE_PCT_FS) and mutant.expect != 'refuse':
        return 'accepted', f'max RMS error {error.max():.3f} % FS'
    return 'silent_wrong', f'accepted with RMS error up to {error.max():.3g} % FS'


def judge_cli(mutant: Mutant, out_dir: Path, timeout_s: float = 120.0) -> tuple[str, str]:
    """(verdict, detail) for one mutant through `python -m balance_calib.cli refit`."""
    from ..calibration_file import load_calibration

    command = [
        sys.executable,
        '-m',
        'balance_calib.cli',
        'refit',
        *map(str, mutant.paths),
        '--balance',
        mutant.balance,
        '--out',
        str(out_dir),
        '--no-diagnosis',
    ]
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return 'hang', f'no answer in {timeout_s:.0f} s'
    lines = done.stderr.strip().splitlines()
    if done.returncode == 2 and len(lines) == 1 and lines[0].startswith('balance-calib refit: '):
        if (out_dir / 'calibration.yaml').exists():
            return 'traceback', 'refused but calibration.yaml written'
        return ('refused' if _names_a_file(lines[0], mutant) else 'unnamed'), lines[0]
    if done.returncode != 0 or lines:
        return 'traceback', f'exit {done.returncode}: {done.stderr.strip()[-300:]}'
    error = calibration_error_pct_fs(load_calibration(out_dir / 'calibration.yaml'), mutant)
    if np.all(error < TOLERANCE_PCT_FS) and mutant.expect != 'refuse':
        return 'accepted', f'max RMS error {error.max():.3f} % FS'
    return 'silent_wrong', f'accepted with RMS error up to {error.max():.3g} % FS'


def run_mutants(
    total: int,
    cli: int,
    workdir: Path,
    *,
    seeds=(0,),
    balances=('lmc6522', 'b660h'),
    on_result: Callable | None = None,
) -> dict:
    """Generate and judge `total` mutants, `cli` of them through the CLI. Returns the counts."""
    per = int(np.ceil(total / (len(seeds) * len(balances))))
    counts = {
        'tried': 0,
        'refused': 0,
        'accepted': 0,
        'silent_wrong': 0,
        'traceback': 0,
        'hang': 0,
        'unnamed': 0,
    }
    by_kind: dict[str, dict[str, int]] = {}
    failures = []
    n = 0
    cli_every = max(total // max(cli, 1), 1) if cli else 0
    for balance in balances:
        for seed in seeds:
            campaign = small_campaign(balance, seed)
            clean = Clean(balance, campaign, tuple(campaign_events(campaign)))
            for mutant in mutants(clean, workdir, seed + 100 * (balance == 'b660h'), per):
                if n >= total:
                    break
                out = workdir / f'out-{mutant.name}'
                via_cli = cli_every and n % cli_every == 0 and n // cli_every < cli
                verdict, detail = (judge_cli if via_cli else judge_in_process)(mutant, out)
                n += 1
                counts['tried'] += 1
                counts[verdict] += 1
                by_kind.setdefault(mutant.kind, {}).setdefault(verdict, 0)
                by_kind[mutant.kind][verdict] += 1
                if verdict in ('silent_wrong', 'traceback', 'hang', 'unnamed'):
                    failures.append((mutant.name, verdict, detail))
                if on_result:
                    on_result(mutant, verdict, detail, via_cli)
    return {'counts': counts, 'by_kind': by_kind, 'failures': failures}


# -- memory of split campaigns --------------------------------------------------------------------

_MEMORY_CHILD = r"""
import json, resource, sys, time
from pathlib import Path
from balance_calib.calibrate.from_bags import RefitSettings, run_refit
paths = sys.argv[3:]
started = time.monotonic()
result = run_refit(paths, sys.argv[1], Path(sys.argv[2]), RefitSettings(plots=False))
def peak_mb():
    # VmHWM is this program's own peak; ru_maxrss also counts the parent's pages before exec
    try:
        for line in open('/proc/self/status'):
            if line.startswith('VmHWM:'):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({'peak_rss_mb': peak_mb(),
                  'seconds': time.monotonic() - started,
                  'sigma': result.report['sigma_pct_fs']['after'],
                  'sessions': result.report.get('sessions')}))
"""


def split_campaign_memory(
    workdir: Path, pauses_s=(0.0, 3600.0, 16 * 3600.0), samples_per_point: int = 10
) -> dict:
    """Peak RSS of full refits (diagnosis on) of one LMC6522 campaign split in two sessions."""
    campaign = small_campaign('lmc6522', 11, samples_per_point)
    events = campaign_events(campaign)
    loads_index = [i for i, e in enumerate(events) if e.topic == LOAD]
    at = loads_index[len(loads_index) // 2]
    results = {}
    for pause in pauses_s:
        pause_ns = int(pause * 1e9)
        first = write_mcap(events[:at], workdir / f'split-{pause:.0f}-a.mcap')
        later = [
            Event(e.log_ns + pause_ns, e.order, e.topic, e.stamp_ns + pause_ns, e.values)
            for e in events[at:]
        ]
        last_gravity = [e for e in events[:at] if e.topic == GRAVITY][-1]
        later.insert(
            0, Event(later[0].log_ns - 1, 0, GRAVITY, later[0].stamp_ns - 1, last_gravity.values)
        )
        second = write_mcap(later, workdir / f'split-{pause:.0f}-b.mcap')
        done = subprocess.run(
            [
                sys.executable,
                '-c',
                _MEMORY_CHILD,
                'lmc6522',
                str(workdir / f'out-split-{pause:.0f}'),
                str(first),
                str(second),
            ],
            capture_output=True,
            text=True,
            timeout=900,
        )
        if done.returncode != 0:
            results[pause] = {
                'error': done.stderr.strip().splitlines()[-1] if done.stderr.strip() else 'failed'
            }
        else:
            results[pause] = json.loads(done.stdout.strip().splitlines()[-1])
    return results


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--mutants', type=int, default=416)
    parser.add_argument('--cli', type=int, default=8, help='how many of them through the CLI')
    parser.add_argument('--seeds', type=int, default=2)
    parser.add_argument(
        '--memory', action='store_true', help='also the split-campaign peak memory'
    )
    parser.add_argument('--verbose', action='store_true')
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix='refit-reliability-') as tmp:
        started = time.monotonic()

        def show(mutant, verdict, detail, via_cli):
            if args.verbose or verdict in ('silent_wrong', 'traceback', 'hang', 'unnamed'):
                print(
                    f'{mutant.name:40s} {"cli" if via_cli else "   "} {verdict:12s} '
                    f'{detail[:150]}',
                    flush=True,
                )

        summary = run_mutants(
            args.mutants, args.cli, Path(tmp), seeds=tuple(range(args.seeds)), on_result=show
        )
        c = summary['counts']
        print(
            f'{c["tried"]} tried, {c["refused"]} refused cleanly, {c["accepted"]} accepted '
            f'correctly, {c["silent_wrong"]} silent-wrong, {c["traceback"]} tracebacks, '
            f'{c["hang"]} hangs, {c["unnamed"]} errors naming no file ({args.cli} through the '
            f'CLI; {time.monotonic() - started:.0f} s)'
        )
        print('by kind (verdict: count):')
        for kind, verdicts in summary['by_kind'].items():
            print(f'  {kind:20s} ' + ', '.join(f'{v} {n}' for v, n in sorted(verdicts.items())))
        if args.memory:
            for pause, result in split_campaign_memory(Path(tmp)).items():
                print(f'split campaign, pause {pause / 3600:.0f} h: {json.dumps(result)}')


if __name__ == '__main__':
    main()
