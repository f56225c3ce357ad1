"""`ros param set` with NaN or inf for a double parameter: the value reaches the node, which
refuses it in one line naming the parameter and its range, and keeps the value it had.
"""

import math
import re

import pytest
from rcl_interfaces.msg import ParameterType
from ros_harness import new_domain_id, NodeProcess, ros

from balance_calib.live.parameters import PARAMETERS
from ros_cli.errors import ToolError
from ros_cli.values import python_to_parameter_value

DOUBLE = ParameterType.PARAMETER_DOUBLE


def test_words_yaml_leaves_as_strings_are_doubles_for_a_double_parameter():
    assert math.isnan(python_to_parameter_value('nan', DOUBLE).double_value)
    assert python_to_parameter_value('inf', DOUBLE).double_value == math.inf
    assert python_to_parameter_value('-inf', DOUBLE).double_value == -math.inf
    assert python_to_parameter_value('1e3', DOUBLE).double_value == 1000.0  # YAML 1.1: a string
    assert python_to_parameter_value('.nan', DOUBLE).type == DOUBLE
    with pytest.raises(ToolError, match="value 'wide' for envelope_margin is not a double"):
        python_to_parameter_value('wide', DOUBLE, 'envelope_margin')
    with pytest.raises(ToolError, match='is not a double'):
        python_to_parameter_value('true', DOUBLE)


@pytest.mark.ros
def test_nan_and_inf_are_refused_by_the_node_naming_the_parameter_and_its_range(tmp_path):
    domain = new_domain_id()
    calibrator = NodeProcess('balance_calibrator', domain, tmp_path, {'diagnostics_period_s': 0.5})
    try:
        for name, text in (
            ('lowpass_hz', 'nan'),
            ('overload_fraction', 'inf'),
            ('envelope_margin', '-inf'),
        ):
            spec = PARAMETERS[name]
            done = ros(
                domain, 'param', 'set', '--timeout', 60, '/balance_calibrator', name, '--', text
            )  # '--': -inf is not an option
            assert done.returncode == 1, done.stdout + done.stderr
            lines = done.stderr.strip().splitlines()
            assert len(lines) == 1, done.stderr
            start = f'ros param set: setting {name} on /balance_calibrator failed: '
            assert lines[0].startswith(start), lines[0]
            reason = lines[0][len(start) :]  # rclpy's range check answers before the node's own
            numbers = {float(n) for n in re.findall(r'[-+]?\d+(?:\.\d*)?(?:e[-+]?\d+)?', reason)}
            assert name in reason and text in reason and {spec.low, spec.high} <= numbers, reason
            kept = ros(domain, 'param', 'get', '/balance_calibrator', name, '--timeout', 60)
            assert kept.stdout.strip() == f'Double value is: {float(spec.default)}', kept.stdout
        assert 'Traceback' not in calibrator.output()
    finally:
        calibrator.stop()
