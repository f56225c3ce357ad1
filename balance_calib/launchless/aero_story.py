"""TM-663 §10.3 without ros2 launch: the replica Euler model flown on the LMC6522, reduced live and
offline through the linear, quadratic and cubic calibrations, against the simulation's truth.

    python -m balance_calib.launchless.aero_story [OUT_DIR] [--q-pa 50000] [--installation upright]

1. balance_calibrator (the memo's cubic matrix, no tare), aero_coefficients (weight and CG
   estimated from the wind-off sweep), balance_recorder and bridge_publisher (a physical wind-on
   run: wind-off α/φ sweep, α = -2 ... 22° at q∞, the model's weight at each attitude, the sting's
   deflection) run as processes on one ROS domain over loopback;
2. the recorded bag goes through `balance-calib reduce --compare linear,quadratic,cubic`;
3. printed: the weight tare found, live against offline, and each model's error against the truth
   (largest over α, and in units of the point's uncertainty u), C_AF at the highest α; the figure
   where the linear matrix departs is OUT/reduce/coefficient_CAF.png.
"""

from __future__ import annotations

import argparse
import csv
import os
from pathlib import Path
import shutil
import stat
import sys
import threading

import numpy as np

from ..commands.run_arguments import (
    add_model_arguments,
    add_wind_on_conditions_arguments,
    DEFAULT_AERO_MODEL,
    wind_on_conditions,
    WindOnConditions,
)
from .processes import close_graph, NodeProcess, story_domain_id
from .processes import wait_until as _wait

MODEL = DEFAULT_AERO_MODEL
# what the story flies: its noise is a long average per point, so that what separates the three
# calibrations is their model, not the scatter (Table 17's σ: -1)
FLIGHT = WindOnConditions(MODEL, 'upright', 50000.0, 0.005)
COEFFICIENTS = ('CAF', 'CY', 'CN', 'Cl', 'Cm', 'Cn', 'CD', 'CL')


def aero_executable(scratch: Path) -> str:
    """The aero_coefficients console script, or (before the package is reinstalled) a script that
    runs the same main() with this interpreter.
    """
    found = shutil.which('aero_coefficients')
    if found:
        return found
    scratch.mkdir(parents=True, exist_ok=True)
    script = scratch / 'aero_coefficients'
    script.write_text(
        f'#!{sys.executable}\nimport sys\nfrom balance_calib.nodes.aero_coefficients import main\n'
        f'sys.exit(main())\n'
    )
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return str(script)


def _six(msg):
    w = msg.wrench
    return [w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z]


def run_story(
    out_dir: Path, flight: WindOnConditions = FLIGHT, *, seed: int = 3, say=print
) -> dict:
    """The story into out_dir: flight.model on the LMC6522 at flight's installation, q∞ and
    point noise; the noise of the simulation from seed.
    """
    model, installation, q_pa = flight.model, flight.installation, flight.q_pa
    noise_sigma_pct_fs = flight.noise_sigma_pct_fs
    from geometry_msgs.msg import WrenchStamped
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from ..aero.pipeline import reduce_bags, ReduceOptions
    from ..aero.report import truth_by_point, write_outputs

    out_dir = Path(out_dir).resolve()
    bag, logs = out_dir / 'bag', out_dir / 'logs'
    if bag.exists():
        raise FileExistsError(f'{bag} exists already: choose a new output directory')
    domain = story_domain_id()
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = Node('aero_story', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    reliable = QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE)
    points, points_wind = [], []
    node.create_subscription(WrenchStamped, '/aero/point', points.append, reliable)
    node.create_subscription(WrenchStamped, '/aero/point_wind', points_wind.append, reliable)
    processes = []
    try:
        processes.append(
            NodeProcess(
                'balance_calibrator',
                domain,
                logs,
                {
                    'installation': installation,
                    'model': 'cubic',
                    'tare_file': str(out_dir / 'calibrator_tare.yaml'),
                },
            )
        )
        processes.append(
            NodeProcess(
                aero_executable(logs),
                domain,
                logs,
                {
                    'model': model,
                    'estimate_weight': True,
                    'calibration_file': 'lmc6522',
                    'installation': installation,
                },
            )
        )
        recorder = NodeProcess(
            'balance_recorder',
            domain,
            logs,
            {
                'output': str(bag),
                'topics': [
                    '/balance/raw',
                    '/model/attitude',
                    '/tunnel/dynamic_pressure',
                    '/aero/truth',
                    '/aero/truth_wind',
                ],
            },
        )
        processes.append(recorder)
        _wait(
            lambda: (
                node.count_subscribers('/model/attitude') >= 1
                and node.count_subscribers('/balance/raw') >= 1
            ),
            30,
            'aero_coefficients and balance_calibrator',
        )
        say(
            f'[aero] ROS_DOMAIN_ID={domain}: {model} on the LMC6522 ({installation}), wind-off '
            f'α/φ sweep, then α = -2 … 22° at q∞ = {q_pa / 1000:g} kPa (point noise '
            f'{noise_sigma_pct_fs:g} % FS); recording to {bag}'
        )
        publisher = NodeProcess(
            'bridge_publisher',
            domain,
            logs,
            {
                'mode': 'wind_on',
                'aero_model': model,
                'installation': installation,
                'dynamic_pressure_pa': q_pa,
                'rate_hz': 100.0,
                'hold_s': 0.5,
                'wind_off_hold_s': 0.3,
                'electrical_zero_mv': 0.0,
                'seed': seed,
                'noise_sigma_pct_fs': noise_sigma_pct_fs,
                'exit_when_done': True,
                'wait_for_subscribers': 2,
                'start_delay_s': 2.0,
            },
        )
        processes.append(publisher)
        if publisher.wait(300) != 0:
            raise RuntimeError(f'bridge_publisher failed; see {publisher.stderr_path}')
        _wait(
            lambda: len(points) >= 13 and len(points_wind) >= 13,
            30,
            'the live points of aero_coefficients',
        )
        if recorder.stop() != 0:
            raise RuntimeError(
                f'balance_recorder did not close cleanly; see {recorder.stderr_path}'
            )
    finally:
        close_graph(processes, executor, node, context)

    reduction = reduce_bags(
        [bag],
        'lmc6522',
        model,
        ReduceOptions(
            compare=['linear', 'quadratic', 'cubic'],
            estimate_weight=True,
            installation=installation,
        ),
    )
    write_outputs(reduction, out_dir / 'reduce')
    with open(out_dir / 'reduce' / 'coefficients.csv', newline='') as handle:
        rows = list(csv.DictReader(handle))
    offline = np.array([[float(r[c]) for c in COEFFICIENTS] for r in rows])
    live = np.array([_six(b) + [_six(w)[0], _six(w)[2]] for b, w in zip(points, points_wind)])
    tare = reduction.main.result.tares[0]
    truth = truth_by_point(reduction)
    say(
        f'[aero] weight tare from {tare.points} wind-off attitudes (load space): W = '
        f'{tare.weight_n:.2f} ± {tare.weight_sigma_n:.2f} N, CG = '
        f'({", ".join(f"{1000 * c:.1f}" for c in tare.cg_m)}) mm (simulated: 250 N at (15, 0, '
        '-4) mm)'
    )
    say(
        f'[aero] live (aero_coefficients) against offline (balance-calib reduce): {len(live)} '
        f'and {len(offline)} held points, largest |difference| '
        f'{np.max(np.abs(live - offline)):.1e}'
    )
    u = np.array(
        [
            np.concatenate([p.uncertainty_body, p.uncertainty_wind[[0, 2]]])
            for p in reduction.main.result.wind_on
        ]
    )
    say(
        "[aero] error against the truth, largest over α (and in units of the point's "
        "uncertainty u, k = 1):"
    )
    say('         ' + ''.join(f'{c:>17}' for c in COEFFICIENTS))
    errors = {}
    for name in ('linear', 'quadratic', 'cubic'):
        column = [c if name == reduction.main.name else f'{c}_{name}' for c in COEFFICIENTS]
        values = np.array([[float(r[c]) for c in column] for r in rows])
        error = np.abs(values - truth)
        errors[name] = error
        say(
            f'  {name:<9}'
            + ''.join(
                f'{np.max(error[:, k]):10.1e} ({np.max(error[:, k] / u[:, k]):3.1f}u)'
                for k in range(len(COEFFICIENTS))
            )
        )
    alpha = float(rows[-1]['alpha_deg'])
    caf = {
        name: float(rows[-1]['CAF' if name == reduction.main.name else f'CAF_{name}'])
        for name in ('linear', 'quadratic', 'cubic')
    }
    say(
        f'[aero] C_AF at α = {alpha:.2f}°: truth {truth[-1, 0]:+.5f}; '
        + ', '.join(f'{name} {value:+.5f}' for name, value in caf.items())
        + f' (u = {u[-1, 0]:.5f})'
    )
    say(
        f'[aero] figures (TM-663 Figs. 12-13 style): {out_dir / "reduce"}/coefficient_*.png; '
        f'the linear departure in C_AF: {out_dir / "reduce" / "coefficient_CAF.png"}; report: '
        f'{out_dir / "reduce" / "report.md"}'
    )
    return {
        'live_vs_offline': float(np.max(np.abs(live - offline))),
        'errors': errors,
        'tare': tare,
    }


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='aero_story', description=' '.join(__doc__.split('\n\n')[0].split())
    )
    parser.add_argument(
        'out', nargs='?', default='demo_out/aero', help='output directory (default demo_out/aero)'
    )
    add_model_arguments(parser, model=False)
    add_wind_on_conditions_arguments(parser, FLIGHT)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        run_story(Path(args.out), wind_on_conditions(args, model=MODEL))
    except (FileExistsError, RuntimeError, TimeoutError, ValueError) as err:
        print(f'aero_story: {err}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
