"""thrust_analyzer as a real process over DDS: inputs in, thrust coefficient out on /diagnostics,
a report on request (~/report) and on shutdown (SIGINT).
"""

import json
import os
import signal
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import FluidPressure
from std_srvs.srv import Trigger

from balance_calib.thrust_stand.nozzle import Nozzle

STATUS_NAME = 'thrust_analyzer: thrust coefficient'
THRUST_N = 2.5
GAUGE_PA = 0.5e6
AMBIENT_PA = 101325.0
TIMEOUT_S = 20.0


@pytest.fixture
def analyzer(tmp_path, ros_domain):
    env = {
        **os.environ,
        'ROS_DOMAIN_ID': str(ros_domain),
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
    }
    log = (tmp_path / 'analyzer.log').open('w')
    process = subprocess.Popen(
        [
            sys.executable,
            '-m',
            'balance_calib.nodes.thrust_analyzer',
            '--ros-args',
            '-p',
            'publish_period_s:=0.1',
            '-p',
            'window_s:=0.5',
            '-p',
            'stale_after_s:=1.0',
            '-p',
            f'report_path:={tmp_path / "firing"}',
        ],
        env=env,
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    yield process, tmp_path
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    log.close()


@pytest.fixture
def ros_node(ros_domain):
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_domain)
    node = rclpy.create_node('thrust_analyzer_test', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    yield node, executor
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def spin_until(executor, predicate, what, process=None, timeout_s=TIMEOUT_S):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if predicate():
            return
        if process is not None and process.poll() is not None:
            pytest.fail(
                f'thrust_analyzer exited with {process.returncode} while waiting for {what}'
            )
    pytest.fail(f'timed out after {timeout_s} s waiting for {what}')


@pytest.mark.ros
def test_analyzer_reports_measured_and_theoretical_thrust_coefficient(analyzer, ros_node):
    process, tmp_path = analyzer
    node, executor = ros_node
    statuses = []
    node.create_subscription(
        DiagnosticArray,
        '/diagnostics',
        lambda msg: statuses.extend(s for s in msg.status if s.name == STATUS_NAME),
        10,
    )

    # before any input the analyzer says which topics it is waiting for
    spin_until(
        executor,
        lambda: any(s.level == DiagnosticStatus.STALE for s in statuses),
        'a STALE status',
        process,
    )
    assert '/balance/wrench' in statuses[-1].message

    wrench_pub = node.create_publisher(WrenchStamped, '/balance/wrench', 10)
    chamber_pub = node.create_publisher(FluidPressure, '/thrust_stand/chamber_pressure', 10)
    ambient_pub = node.create_publisher(FluidPressure, '/thrust_stand/ambient_pressure', 10)

    def publish_inputs():
        wrench = WrenchStamped()
        wrench.header.stamp = node.get_clock().now().to_msg()
        wrench.wrench.force.x = THRUST_N
        wrench_pub.publish(wrench)
        chamber_pub.publish(FluidPressure(fluid_pressure=GAUGE_PA))
        ambient_pub.publish(FluidPressure(fluid_pressure=AMBIENT_PA))

    node.create_timer(0.02, publish_inputs)

    def firing_status():
        for status in reversed(statuses):
            values = {kv.key: kv.value for kv in status.values}
            if values.get('firing') == 'true':
                return values
        return None

    spin_until(
        executor,
        lambda: firing_status() is not None,
        'a thrust-coefficient status while firing',
        process,
    )
    values = firing_status()
    nozzle = Nozzle()
    chamber_pa = GAUGE_PA + AMBIENT_PA
    theory = nozzle.performance(chamber_pa, AMBIENT_PA)
    assert float(values['cf_measured']) == pytest.approx(
        THRUST_N / (chamber_pa * nozzle.throat_area_m2), rel=1e-8
    )
    assert float(values['cf_theory']) == pytest.approx(theory.cf, rel=1e-8)
    assert float(values['thrust_theory_n']) == pytest.approx(theory.thrust_n, rel=1e-8)
    assert float(values['chamber_pressure_pa']) == pytest.approx(chamber_pa)
    assert float(values['pe_over_pc']) == pytest.approx(theory.pe_over_pc, rel=1e-8)
    # constant inputs: only the calibration (1 %) and throat (2 x 0.4 %) uncertainties remain
    assert float(values['cf_measured_sigma']) == pytest.approx(
        float(values['cf_measured']) * (0.01**2 + (2 * 1e-5 / 2.5e-3) ** 2) ** 0.5, rel=1e-6
    )

    # the report on request ...
    client = node.create_client(Trigger, '/thrust_analyzer/report')
    spin_until(executor, lambda: client.service_is_ready(), 'the ~/report service', process)
    future = client.call_async(Trigger.Request())
    spin_until(executor, future.done, 'the ~/report reply', process)
    assert future.result().success, future.result().message
    report = json.loads((tmp_path / 'firing.json').read_text())
    assert report['measured']['cf'] == pytest.approx(float(values['cf_measured']), rel=1e-6)
    assert report['theory']['cf'] == pytest.approx(theory.cf, rel=1e-12)

    # ... and again on shutdown
    (tmp_path / 'firing.json').unlink()
    (tmp_path / 'firing.md').unlink()
    process.send_signal(signal.SIGINT)
    assert process.wait(TIMEOUT_S) == 0
    assert (tmp_path / 'firing.json').exists() and (tmp_path / 'firing.md').exists()
