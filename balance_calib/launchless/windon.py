"""`launchless_scripts/windon OUT`: record a simulated wind-on run into the bag `reduce` takes.

    launchless_scripts/windon OUT [--model euler_replica_lmc6522] [--q-pa 50000]
                                  [--installation upright] [--alpha-deg=-2,22,2] [--hold-s 0.5]
                                  [--wind-off-hold-s 0.3] ...

First the balance's electrical zero, as a laboratory takes it before mounting the model:
balance_calibrator runs beside a bridge_publisher of the empty balance and its ~/zero averages the
outputs (TM-663 §5(4): the zero belongs in output space). Then balance_recorder (its default
topics: every topic of docs/interfaces.md, plus the simulation's /aero/truth and /aero/truth_wind)
and bridge_publisher in wind-on mode with a model (config/models: the physical run of TM-663
§10.3, a wind-off α/φ sweep, the α sweep at q∞, the same wind-off sweep after it, with
/model/attitude and /tunnel/dynamic_pressure beside /balance/raw) run on this shell's ROS domain,
the calibrator still running: its /diagnostics in the bag state the zero, which `reduce` subtracts,
and the sweeps before and after the run bracket the drift of the zero. The publisher starts when
the recorder has subscribed and gives up after --subscriber-timeout-s; when the run is over the
recorder is stopped, the bag OUT is closed (metadata.yaml written) and the `balance-calib reduce`
command line for it is printed. A failed run removes the bag it created. Ctrl-C stops the nodes;
the bag then holds the run so far.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from typing import Callable, Sequence

from ..aero.bag_io import (
    ATTITUDE_TOPIC,
    DYNAMIC_PRESSURE_TOPIC,
    RAW_TOPIC,
    TRUTH_TOPIC,
    TRUTH_WIND_TOPIC,
)
from ..commands.run_arguments import (
    add_model_arguments,
    add_simulated_balance_arguments,
    add_wind_on_conditions_arguments,
    DEFAULT_AERO_MODEL,
    positive_number,
    simulated_balance,
    SimulatedBalance,
    wind_on_conditions,
    WindOnConditions,
)
from .processes import ros_args

DEFAULT_MODEL = DEFAULT_AERO_MODEL
TRUTH_TOPICS = (TRUTH_TOPIC, TRUTH_WIND_TOPIC)  # simulation only, what `reduce` compares with
REDUCE_TOPICS = (RAW_TOPIC, ATTITUDE_TOPIC, DYNAMIC_PRESSURE_TOPIC)  # what `reduce` reads
STOP_TIMEOUT_S = 10.0
ZERO_SERVICE = '/balance_calibrator/zero'
EMPTY_BALANCE_S = 5.0  # the empty balance's profile, looped until ~/zero has its samples
ZERO_SAMPLES = 100  # averaged by ~/zero


class WindOnError(RuntimeError):
    """One line for stderr: what failed, and where its node said why."""


@dataclass(frozen=True)
class RunDescription:
    """A simulated wind-on run as windon records it: the balance (its seed: the noise's), what is
    flown (model, installation, q∞, point noise), the sweep's α and hold times, bridge samples
    per second, and how long the nodes are waited for.
    """

    balance: SimulatedBalance = SimulatedBalance(seed=0)
    flight: WindOnConditions = WindOnConditions()
    alpha_deg: tuple[float, float, float] = (-2.0, 22.0, 2.0)
    hold_s: float = 0.5
    wind_off_hold_s: float = 0.3
    rate_hz: float = 200.0
    subscriber_timeout_s: float = 30.0
    run_timeout_s: float = 600.0


@dataclass(frozen=True)
class WindOnRun:
    """What a recorded run left: the bag and its per-topic message counts."""

    bag: Path
    message_counts: dict[str, int]
    reduce_command: list[str]


def recorder_topics() -> list[str]:
    """The recorder's default topics (interfaces.md) and the simulation's truth."""
    from ..bags.recorder_parameters import DEFAULT_TOPICS

    return list(DEFAULT_TOPICS) + [t for t in TRUTH_TOPICS if t not in DEFAULT_TOPICS]


def publisher_parameters(run: RunDescription) -> dict:
    """bridge_publisher's parameters for a physical wind-on run (nodes/bridge_publisher.py)."""
    start, end, step = (float(v) for v in run.alpha_deg)
    return {
        'mode': 'wind_on',
        'aero_model': run.flight.model,
        'balance': run.balance.name,
        'effects': run.balance.effects,
        'dynamic_pressure_pa': run.flight.q_pa,
        'installation': run.flight.installation,
        'alpha_start_deg': start,
        'alpha_end_deg': end,
        'alpha_step_deg': step,
        'hold_s': run.hold_s,
        'wind_off_hold_s': run.wind_off_hold_s,
        'rate_hz': run.rate_hz,
        'seed': run.balance.seed,
        'noise_sigma_pct_fs': run.flight.noise_sigma_pct_fs,
        'exit_when_done': True,
        'wait_for_subscribers': 1,
        'wait_for_subscribers_timeout_s': run.subscriber_timeout_s,
    }


def calibrator_parameters(run: RunDescription, tare_file: Path) -> dict:
    """balance_calibrator's: the balance's shipped calibration, ~/zero over ZERO_SAMPLES (given
    subscriber_timeout_s for its samples), its zero kept in a scratch tare_file (not beside the
    user's files, not restored by the next run).
    """
    return {
        'calibration_file': run.balance.name,
        'installation': run.flight.installation,
        'tare_samples': ZERO_SAMPLES,
        'tare_timeout_s': run.subscriber_timeout_s,
        'tare_file': str(tare_file),
    }


def empty_balance_parameters(run: RunDescription, profile_csv: Path) -> dict:
    """bridge_publisher's for the empty balance (zero loads, the electrical zero and noise)."""
    return {
        'mode': 'wind_on',
        'balance': run.balance.name,
        'effects': run.balance.effects,
        'profile_csv': str(profile_csv),
        'loop': True,
        'rate_hz': run.rate_hz,
        'seed': run.balance.seed,
        'noise_sigma_pct_fs': run.flight.noise_sigma_pct_fs,
        'wait_for_subscribers': 1,
        'wait_for_subscribers_timeout_s': run.subscriber_timeout_s,
    }


def write_empty_balance_csv(directory: Path) -> Path:
    """A load profile (simulation/wind_on.py csv_profile) of EMPTY_BALANCE_S s at zero load."""
    path = Path(directory) / 'empty_balance.csv'
    path.write_text(
        'time_s,FX,FY,FZ,MX,MY,MZ\n0,0,0,0,0,0,0\n' + f'{EMPTY_BALANCE_S:g},0,0,0,0,0,0\n'
    )
    return path


def take_electrical_zero(
    env: dict, timeout_s: float, calibrator: subprocess.Popen, stop: Callable[[], bool]
) -> str:
    """Call balance_calibrator's ~/zero on env's ROS domain; its reply. WindOnError when the
    calibrator exits, does not answer within timeout_s or refuses the window.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from std_srvs.srv import Trigger

    context = Context()
    rclpy.init(
        context=context,
        domain_id=int(env.get('ROS_DOMAIN_ID') or 0),
        signal_handler_options=SignalHandlerOptions.NO,  # Ctrl-C stays ours
    )
    node = rclpy.create_node('windon_zero', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    deadline = time.monotonic() + timeout_s

    def spin_until(done: Callable[[], bool], what: str) -> None:
        while not done():
            if calibrator.poll() is not None:
                raise WindOnError(
                    f'balance_calibrator exited with status {calibrator.returncode} before '
                    f'{what} (see its lines above)'
                )
            if stop():
                raise KeyboardInterrupt('interrupted while taking the electrical zero')
            if time.monotonic() > deadline:
                raise WindOnError(f'no {what} within {timeout_s:g} s')
            executor.spin_once(timeout_sec=0.1)

    try:
        client = node.create_client(Trigger, ZERO_SERVICE)
        spin_until(client.service_is_ready, f'{ZERO_SERVICE} service')
        future = client.call_async(Trigger.Request())
        spin_until(future.done, f'reply from {ZERO_SERVICE}')
        reply = future.result()
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    if reply is None or not reply.success:
        raise WindOnError(f'{ZERO_SERVICE}: {"no reply" if reply is None else reply.message}')
    return reply.message


def reduce_command(bag: Path, run: RunDescription) -> list[str]:
    """The `balance-calib reduce` command line for the bag (the balance's shipped matrices)."""
    return [
        'balance-calib',
        'reduce',
        str(bag),
        '--calibration',
        run.balance.name,
        '--model',
        run.flight.model,
        '--installation',
        run.flight.installation,
        '--out',
        str(bag.parent / f'{bag.name}_reduce'),
    ]


def _stop(process: subprocess.Popen, timeout_s: float = STOP_TIMEOUT_S) -> int:
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.returncode


def record_wind_on_run(
    out: Path,
    run: RunDescription = RunDescription(),
    *,
    say: Callable[[str], None] = print,
    env: dict | None = None,
) -> WindOnRun:
    """Run balance_recorder and bridge_publisher (wind-on) until the run is over; the bag is out.

    The nodes print on this process's stdout and stderr. Raises WindOnError (the bag removed) when
    a node fails or the run outlasts run.run_timeout_s, FileExistsError when out exists already.
    """
    out = Path(out).absolute()
    if out.exists():
        raise FileExistsError(f'{out} exists already; choose a new bag directory')
    recorder_args = ros_args({'output': str(out), 'topics': recorder_topics()})
    scratch = Path(tempfile.mkdtemp(prefix='windon-'))
    calibrator_args = ros_args(calibrator_parameters(run, scratch / 'zero.tare.yaml'))
    publisher_args = ros_args(publisher_parameters(run))
    env = dict(os.environ if env is None else env)
    processes: dict[str, subprocess.Popen] = {}
    interrupted = False

    def on_signal(signum, frame):
        nonlocal interrupted
        interrupted = True

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        # own sessions: a terminal's Ctrl-C reaches the nodes only through us, in order
        calibrator = processes['balance_calibrator'] = subprocess.Popen(
            ['balance_calibrator', *calibrator_args], env=env, start_new_session=True
        )
        empty_args = ros_args(empty_balance_parameters(run, write_empty_balance_csv(scratch)))
        processes['empty balance'] = subprocess.Popen(
            ['bridge_publisher', *empty_args], env=env, start_new_session=True
        )
        balance, flight = run.balance.name, run.flight
        say(f'windon: the {balance} empty: its electrical zero with {ZERO_SERVICE}')
        reply = take_electrical_zero(
            env, run.subscriber_timeout_s, calibrator, lambda: interrupted
        )
        _stop(processes.pop('empty balance'))
        say(f'windon: {reply}')
        processes['balance_recorder'] = subprocess.Popen(
            ['balance_recorder', *recorder_args], env=env, start_new_session=True
        )
        processes['bridge_publisher'] = subprocess.Popen(
            ['bridge_publisher', *publisher_args], env=env, start_new_session=True
        )
        say(
            f'windon: recording {flight.model} on the {balance} ({flight.installation}, '
            f'q∞ {flight.q_pa:g} Pa) into {out}'
        )
        publisher, recorder = processes['bridge_publisher'], processes['balance_recorder']
        deadline = time.monotonic() + run.run_timeout_s
        while publisher.poll() is None and not interrupted:
            if recorder.poll() is not None:
                _stop(publisher)
                raise WindOnError(
                    f'balance_recorder exited with status {recorder.returncode} '
                    'before the run was over (see its lines above)'
                )
            if time.monotonic() > deadline:
                _stop(publisher)
                raise WindOnError(f'the run did not end within {run.run_timeout_s:g} s')
            time.sleep(0.1)
        if interrupted:
            _stop(publisher)
            status = _stop(recorder)
            _stop(calibrator)
            raise KeyboardInterrupt(
                f'interrupted; the bag {out} holds the run so far'
                + ('' if status == 0 else f' (recorder status {status})')
            )
        if publisher.returncode != 0:
            _stop(recorder)
            raise WindOnError(
                f'bridge_publisher exited with status {publisher.returncode} (see its lines above)'
            )
        status = _stop(recorder)
        if status != 0:
            raise WindOnError(f'balance_recorder did not close the bag cleanly (status {status})')
    except WindOnError:
        for process in processes.values():
            _stop(process)
        shutil.rmtree(out, ignore_errors=True)
        raise
    finally:
        for process in processes.values():
            _stop(process)
        shutil.rmtree(scratch, ignore_errors=True)
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    counts = recorded_counts(out)
    missing = [t for t in REDUCE_TOPICS if not counts.get(t)]
    if missing:
        raise WindOnError(f'bag {out}: no messages on {", ".join(missing)}, which reduce needs')
    return WindOnRun(out, counts, reduce_command(out, run))


def recorded_counts(bag: Path) -> dict[str, int]:
    """Messages per topic, from the metadata.yaml the recorder wrote when it closed the bag."""
    import yaml

    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    return {
        t['topic_metadata']['name']: int(t['message_count'])
        for t in info['topics_with_message_count']
    }


def _alpha(text: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.split(','))
    except ValueError:
        values = ()
    if len(values) != 3 or not values[2] > 0 or values[1] < values[0]:
        raise argparse.ArgumentTypeError(f'{text!r}: give START,END,STEP in degrees, STEP > 0')
    start, end, step = values
    return start, end, step


def add_sweep_arguments(parser, defaults: RunDescription) -> None:
    """The run's own options: its α sweep, hold times, rate and the subscriber wait."""
    parser.add_argument(
        '--alpha-deg',
        type=_alpha,
        default=defaults.alpha_deg,
        help='wind-on α sweep START,END,STEP in degrees (default -2,22,2; '
        'spell a negative START as --alpha-deg=-4,20,4)',
    )
    parser.add_argument(
        '--hold-s',
        type=positive_number,
        default=defaults.hold_s,
        help=f'seconds at each wind-on α (default {defaults.hold_s:g})',
    )
    parser.add_argument(
        '--wind-off-hold-s',
        type=positive_number,
        default=defaults.wind_off_hold_s,
        help=f'seconds at each wind-off attitude (default {defaults.wind_off_hold_s:g})',
    )
    parser.add_argument(
        '--rate-hz',
        type=positive_number,
        default=defaults.rate_hz,
        help=f'bridge samples per second (default {defaults.rate_hz:g})',
    )
    parser.add_argument(
        '--subscriber-timeout-s',
        type=positive_number,
        default=defaults.subscriber_timeout_s,
        help='bridge_publisher gives up when the recorder has not subscribed '
        f'within this time, s (default {defaults.subscriber_timeout_s:g})',
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='windon',
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=__doc__.split('\n\n', 2)[2].strip(),
        epilog='Then: the printed balance-calib reduce command (e.g. balance-calib reduce OUT '
        '--calibration lmc6522 --model euler_replica_lmc6522 --out OUT_reduce).',
    )
    parser.add_argument('out', help='bag directory to create (it must not exist)')
    defaults = RunDescription()
    add_model_arguments(parser, model_default=defaults.flight.model)
    add_simulated_balance_arguments(parser, defaults.balance)
    add_wind_on_conditions_arguments(parser, defaults.flight)
    add_sweep_arguments(parser, defaults)
    return parser


def run_description(args: argparse.Namespace) -> RunDescription:
    """The run the parsed command line describes."""
    return RunDescription(
        simulated_balance(args),
        wind_on_conditions(args),
        args.alpha_deg,
        args.hold_s,
        args.wind_off_hold_s,
        args.rate_hz,
        args.subscriber_timeout_s,
    )


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.seed < 0:
        print(f'windon: --seed {args.seed}: a seed is not negative', file=sys.stderr)
        return 2
    try:
        run = record_wind_on_run(Path(args.out), run_description(args))
    except (FileExistsError, WindOnError) as error:
        print(f'windon: {error}', file=sys.stderr)
        return 1
    except KeyboardInterrupt as error:
        print(f'windon: {error or "interrupted"}', file=sys.stderr)
        return 130
    counts = ', '.join(f'{topic} {count}' for topic, count in sorted(run.message_counts.items()))
    print(f'windon: bag {run.bag} closed: {counts}')
    print('windon: reduce it with: ' + ' '.join(run.reduce_command))
    return 0


if __name__ == '__main__':
    sys.exit(main())
