"""The whole story without ros2 launch: a calibration campaign over DDS, recorded, refitted by the
calibrator's ~/refit, then wind-on through the new calibration.

    launchless_scripts/campaign [OUT_DIR] [--effects SPEC] [--installations upright,inverted]

1. balance_calibrator (memo matrices at first, calibration_bags = OUT/bag), balance_recorder
   (OUT/bag) and bridge_publisher in calibration mode (the Appendix schedule, fast timing) run as
   processes on one ROS domain over loopback;
2. when the publisher has played the schedule the recorder is stopped (the bag closes cleanly);
3. ~/refit fits the bag (report in OUT/report) and the calibrator swaps to the new calibration;
4. for each installation, bridge_publisher plays a wind-on α sweep, ~/zero takes the electrical
zero on its wind-off
   samples, and the mean /balance/wrench over every held point is compared with the true tunnel
   load (/balance/truth).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
import json
import os
from pathlib import Path
import sys
import threading
import time

import numpy as np

from ..commands.run_arguments import (
    add_simulated_balance_arguments,
    simulated_balance,
    SimulatedBalance,
)
from .processes import close_graph, NodeProcess, story_domain_id
from .processes import wait_until as _wait


@dataclass(frozen=True)
class CampaignStory:
    """What the story runs: the simulated balance (its effects undeclared to the refit), the
    wind-on installations, the campaign's timing as played (bridge samples per second, seconds per
    point and per transition), the balance temperature of the wind-on runs, and whether the first
    installation is flown once more through the base model (when an effect was adopted).
    """

    balance: SimulatedBalance = SimulatedBalance(seed=1)
    installations: tuple[str, ...] = ('upright', 'inverted')
    rate_hz: float = 200.0
    point_duration_s: float = 0.1
    transition_s: float = 0.03
    wind_on_temperature_c: float = 20.0
    compare_base: bool = False


@dataclass
class StoryResult:
    refit_success: bool
    refit_message: str
    report: dict
    # installation -> (held points, 6) errors
    wind_on_error_pct_fs: dict = field(default_factory=dict)
    bag: Path | None = None
    report_dir: Path | None = None


def graph_parameter(node: str, name: str):
    """Parameter `name` of `node` in the shipped config/graph_params.yaml (what the graph runs)."""
    import yaml

    from ..config import resolve_config_path

    shipped = yaml.safe_load(resolve_config_path('graph_params').read_text())
    return shipped[node]['ros__parameters'][name]


def run_story(
    out_dir: Path,
    story: CampaignStory = CampaignStory(),
    *,
    domain_id: int | None = None,
    say=print,
) -> StoryResult:
    """The story on domain_id (default: a free one, story_domain_id) into out_dir."""
    from geometry_msgs.msg import WrenchStamped
    from rcl_interfaces.srv import SetParameters
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_srvs.srv import Trigger

    balance, effects, seed = story.balance.name, story.balance.effects, story.balance.seed
    rate_hz, installations = story.rate_hz, story.installations
    wind_on_temperature_c = story.wind_on_temperature_c
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    bag = out_dir / 'bag'
    if bag.exists():
        raise FileExistsError(f'{bag} exists already: choose a new output directory')
    report_dir = out_dir / 'report'
    logs = out_dir / 'logs'
    domain = domain_id if domain_id is not None else story_domain_id()
    # real DDS, never off this machine
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = Node('campaign_story', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=lambda: _spin(executor), daemon=True)
    spinner.start()
    reliable = QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE)
    wrenches, truths = [], []
    node.create_subscription(WrenchStamped, '/balance/wrench', wrenches.append, reliable)
    node.create_subscription(WrenchStamped, '/balance/truth', truths.append, reliable)
    # counted by bridge_publisher's wait_for_subscribers, so it starts only once we listen
    node.create_subscription(WrenchStamped, '/balance/raw', lambda msg: None, reliable)
    processes = []
    # a calibration applies the rated loads plus the calibration body's weight: the shipped graph's
    # overload limit, which allows for them
    overload_fraction = graph_parameter('balance_calibrator', 'overload_fraction')
    try:
        calibrator = NodeProcess(
            'balance_calibrator',
            domain,
            logs,
            {
                'balance': balance,
                'calibration_bags': [str(bag)],
                'report_dir': str(report_dir),
                'tare_samples': 100,
                'overload_fraction': overload_fraction,
            },
        )
        processes.append(calibrator)
        recorder = NodeProcess('balance_recorder', domain, logs, {'output': str(bag)})
        processes.append(recorder)
        say(
            f'[campaign] ROS_DOMAIN_ID={domain}: calibration campaign of {balance} over DDS '
            f'({rate_hz:g} Hz, {story.point_duration_s:g} s per point), recording to {bag}'
            + (f'; undeclared effects: {effects}' if effects else '')
        )
        publisher = NodeProcess(
            'bridge_publisher',
            domain,
            logs,
            {
                'mode': 'calibration',
                'balance': balance,
                'rate_hz': rate_hz,
                'point_duration_s': story.point_duration_s,
                'transition_s': story.transition_s,
                'effects': effects,
                'seed': seed,
                'exit_when_done': True,
                'wait_for_subscribers': 2,
            },
        )
        processes.append(publisher)
        code = publisher.wait(3600)
        if code != 0:
            raise RuntimeError(f'bridge_publisher failed ({code}); see {publisher.stderr_path}')
        time.sleep(0.5)  # let the last samples reach the recorder before it closes the bag
        if recorder.stop() != 0:
            raise RuntimeError(
                f'balance_recorder did not close cleanly; see {recorder.stderr_path}'
            )
        say('[campaign] campaign recorded; calling /balance_calibrator/refit ...')
        client = node.create_client(Trigger, '/balance_calibrator/refit')
        _wait(client.service_is_ready, 30, 'the ~/refit service')
        future = client.call_async(Trigger.Request())
        _wait(future.done, 600, 'the ~/refit reply')
        reply = future.result()
        say(f'[campaign] refit: success={reply.success}: {reply.message}')
        reports = sorted(report_dir.glob('*/report.json'), key=lambda p: p.stat().st_mtime)
        report = json.loads(reports[-1].read_text()) if reports else {}
        result = StoryResult(
            reply.success,
            reply.message,
            report,
            {},
            bag,
            reports[-1].parent if reports else report_dir,
        )
        if not reply.success:
            return result

        setter = node.create_client(SetParameters, '/balance_calibrator/set_parameters')
        _wait(setter.service_is_ready, 30, 'the calibrator parameter service')
        from balance_calib.config import load_balance_config

        capacity = load_balance_config(balance).capacity
        runs = [(installation, 'adopted') for installation in installations]
        if story.compare_base and report.get('adopted'):
            # the same wind-on without the effect's terms
            runs.append((installations[0], report['base_model']))
        for installation, model in runs:
            request = SetParameters.Request()
            request.parameters = [
                Parameter('installation', value=installation).to_parameter_msg(),
                Parameter('model', value=model).to_parameter_msg(),
            ]
            done = setter.call_async(request)
            _wait(done.done, 10, 'set installation')
            wrenches.clear()
            truths.clear()
            # the simulated model weighs nothing: its wind-off outputs are the electrical zero
            # (~/zero, output space); a model with weight would take ~/zero before mounting and
            # ~/tare after
            tare_client = node.create_client(Trigger, '/balance_calibrator/zero')
            _wait(tare_client.service_is_ready, 10, 'the ~/zero service')
            tare = tare_client.call_async(Trigger.Request())
            wind = NodeProcess(
                'bridge_publisher',
                domain,
                logs,
                {
                    'mode': 'wind_on',
                    'balance': balance,
                    'installation': installation,
                    'rate_hz': rate_hz,
                    'wind_off_s': 1.0,
                    'hold_s': 0.5,
                    'alpha_step_deg': 4.0,
                    'noise_sigma_pct_fs': 0.005,
                    'exit_when_done': True,
                    'wait_for_subscribers': 2,
                    'seed': seed + 1,
                    'effects': effects,
                    'temperature_c': wind_on_temperature_c,
                },
            )
            processes.append(wind)
            if wind.wait(300) != 0:
                raise RuntimeError(f'wind-on publisher failed; see {wind.stderr_path}')
            _wait(tare.done, 10, 'the ~/zero reply')
            _wait(lambda: len(wrenches) >= len(truths) > 0, 10, 'the wind-on wrenches')
            errors = _held_point_errors(truths, wrenches, capacity)
            result.wind_on_error_pct_fs[f'{installation}/{model}'] = errors
            worst = np.max(np.abs(errors), axis=0)
            say(
                f'[campaign] wind-on at {wind_on_temperature_c:g} °C, {installation} '
                f'installation, {model} model: {len(errors)} held α points, worst |mean error| '
                '% FS: '
                + ', '.join(
                    f'{c} {w:.3f}' for c, w in zip(('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ'), worst)
                )
            )
        return result
    finally:
        close_graph(processes, executor, node, context)
        spinner.join(timeout=5)


def _spin(executor):
    try:
        executor.spin()
    except Exception:
        pass


def _held_point_errors(truths, wrenches, capacity) -> np.ndarray:
    def by_stamp(messages):
        return {
            (m.header.stamp.sec, m.header.stamp.nanosec): (
                m.wrench.force.x,
                m.wrench.force.y,
                m.wrench.force.z,
                m.wrench.torque.x,
                m.wrench.torque.y,
                m.wrench.torque.z,
            )
            for m in messages
        }

    true, measured = by_stamp(truths), by_stamp(wrenches)
    stamps = sorted(set(true) & set(measured))
    t = np.array([true[s] for s in stamps])
    m = np.array([measured[s] for s in stamps])
    held = np.any(t != 0, axis=1)
    conditions, index = np.unique(t[held], axis=0, return_inverse=True)
    index = index.ravel()
    return np.array(
        [
            (m[held][index == k].mean(axis=0) - load) / np.abs(capacity) * 100
            for k, load in enumerate(conditions)
        ]
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='campaign', description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        'out',
        nargs='?',
        default='demo_out',
        help='directory for the run (a new campaign_<time> inside it; default demo_out)',
    )
    add_simulated_balance_arguments(parser, CampaignStory().balance)
    parser.add_argument(
        '--installations',
        default='upright,inverted',
        help=(
            'wind-on installations to run, comma-separated (TM-663 §10.2; default '
            'upright,inverted)'
        ),
    )
    parser.add_argument(
        '--rate',
        type=float,
        default=200.0,
        help='bridge samples per second that bridge_publisher plays (default 200)',
    )
    parser.add_argument(
        '--point-duration',
        type=float,
        default=0.1,
        help='seconds of samples per load point as played; the simulated balance still warms '
        'and drifts like a real campaign (default 0.1)',
    )
    parser.add_argument(
        '--wind-on-temperature',
        type=float,
        default=20.0,
        help='balance temperature during the wind-on runs, °C',
    )
    return parser


def campaign_story(args: argparse.Namespace) -> CampaignStory:
    """The story the parsed command line asks for (the base model flown too when effects are
    given).
    """
    return CampaignStory(
        simulated_balance(args),
        tuple(i for i in args.installations.split(',') if i),
        rate_hz=args.rate,
        point_duration_s=args.point_duration,
        wind_on_temperature_c=args.wind_on_temperature,
        compare_base=bool(args.effects),
    )


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    if args.seed < 0:
        print(f'campaign: --seed {args.seed}: a seed is not negative', file=sys.stderr)
        return 2
    out = Path(args.out) / time.strftime('campaign_%Y%m%dT%H%M%S')
    try:
        domain_id = story_domain_id()
    except ValueError as err:
        print(f'campaign: {err}', file=sys.stderr)
        return 2
    story = campaign_story(args)
    result = run_story(out, story, domain_id=domain_id)
    if result.report:
        report = result.report
        print(f'[campaign] report: {result.report_dir / "report.md"}')
        print(
            '[campaign] effects found: '
            f'{", ".join(e["name"] for e in report["effects"]) or "none"}; σ before -> after (% '
            'FS): '
            + ', '.join(
                f'{c} '
                f'{report["sigma_pct_fs"]["before"][c]:.3f}->{report["sigma_pct_fs"]["after"][c]:.3f}'
                for c in report['sigma_pct_fs']['before']
            )
        )
    return 0 if result.refit_success else 1


if __name__ == '__main__':
    sys.exit(main())
