"""Every node declares its table through rclpy with descriptors (description, range, read-only)
and refuses a bad value from the command line in one line naming the parameter, exit status 1.
"""

import math

import pytest
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import DescribeParameters, GetParameters, SetParameters
import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import new_domain_id, NodeProcess, Probe

from balance_calib.node_parameters import TABLES
from balance_calib.nodes._parameters import declare_table
from balance_calib.parameter_table import ParameterError

pytestmark = pytest.mark.ros

ROS_TYPE = {
    'bool': ParameterType.PARAMETER_BOOL,
    'integer': ParameterType.PARAMETER_INTEGER,
    'double': ParameterType.PARAMETER_DOUBLE,
    'string': ParameterType.PARAMETER_STRING,
    'string_array': ParameterType.PARAMETER_STRING_ARRAY,
    'double_array': ParameterType.PARAMETER_DOUBLE_ARRAY,
}


@pytest.fixture
def context():
    made = Context()
    rclpy.init(context=made, domain_id=new_domain_id())
    yield made
    rclpy.try_shutdown(context=made)


def declared(context, node: str, overrides=()) -> tuple[Node, dict]:
    made = Node(f'table_of_{node}', context=context, parameter_overrides=list(overrides))
    return made, declare_table(made, TABLES[node])


@pytest.mark.parametrize('node', TABLES)
def test_each_table_declares_with_its_descriptors(context, node):
    made, values = declared(context, node)
    try:
        for name, spec in TABLES[node].items():
            described = made.describe_parameter(name)
            assert (
                described.description == spec.description
                and described.type == ROS_TYPE[spec.kind]
                and described.read_only == spec.read_only
            ), name
            assert values[name] == (spec.default if spec.has_default else None), name
            constrained = spec.low_open or bool(spec.choices)  # what a closed range cannot say
            assert (described.additional_constraints != '') == constrained, name
            ranges = list(described.floating_point_range) + list(described.integer_range)
            if spec.low is None and spec.high is None:
                assert ranges == [], name
                continue
            (bounds,) = ranges
            unbounded = 2**63 - 1 if spec.kind == 'integer' else math.inf
            low = (
                -unbounded - (spec.kind == 'integer')
                if spec.low is None
                else spec.low + (spec.kind == 'integer' and spec.low_open)
            )
            assert bounds.from_value == low, name
            assert bounds.to_value == (unbounded if spec.high is None else spec.high), name
    finally:
        made.destroy_node()


def test_overrides_take_the_parameters_type_and_bad_ones_are_refused(context):
    made, values = declared(
        context,
        'bridge_publisher',
        [Parameter('rate_hz', value=200), Parameter('model_cg_m', value=[0, 0, 1])],
    )
    try:
        assert values['rate_hz'] == 200.0 and type(values['rate_hz']) is float
        assert made.get_parameter('rate_hz').type_ == Parameter.Type.DOUBLE
        assert values['model_cg_m'] == [0.0, 0.0, 1.0]
        # read at start-up only: a set while it runs is refused by rclpy, the value kept
        result = made.set_parameters([Parameter('rate_hz', value=5.0)])[0]
        assert not result.successful and 'read-only' in result.reason
        assert made.get_parameter('rate_hz').value == 200.0
    finally:
        made.destroy_node()
    with pytest.raises(ParameterError, match=r"^parameter speed must be a number, not 'fast'$"):
        declared(context, 'bridge_publisher', [Parameter('speed', value='fast')])


# a bad value on each node's command line: (node, parameters, what its one line says)
BAD_STARTS = [
    (
        'balance_calibrator',
        {'tare_samples': 5},
        'cannot start: invalid parameter: parameter tare_samples must be in [10, 1e+06], not 5',
    ),
    ('bridge_publisher', {'rate_hz': 0.0}, 'parameter rate_hz must be in (0, inf), not 0'),
    ('bridge_publisher', {'seed': 'fast'}, "parameter seed must be a number, not 'fast'"),
    ('balance_recorder', {'topics': 5}, 'parameter topics must be a list of strings, not 5'),
    ('thrust_analyzer', {'gamma': 1.0}, 'parameter gamma must be in (1, inf), not 1'),
    (
        'aero_coefficients',
        {'min_samples': 0},
        'aero_coefficients: parameter min_samples must be in [1, inf), not 0',
    ),
    (
        'balance_daq',
        {'transport': 'can'},
        "parameter transport must be one of serial, tcp, udp (transport = 'can' given)",
    ),
]


def test_a_bad_value_stops_each_node_with_one_line_naming_it(tmp_path):
    started = [
        NodeProcess(node, new_domain_id(), tmp_path, parameters)
        for node, parameters, _ in BAD_STARTS
    ]  # all at once: start-up is the cost
    try:
        statuses = [process.wait(60.0) for process in started]
    finally:
        for process in started:
            process.stop()
    for process, status, (node, _, said) in zip(started, statuses, BAD_STARTS):
        lines = [line for line in process.output().splitlines() if line.strip()]
        assert status == 1 and len(lines) == 1, (node, status, lines)
        assert lines[0].startswith('[ERROR]') and lines[0].endswith(f'[{node}]: {said}'), lines


def test_a_running_node_describes_its_table_over_dds_and_keeps_read_only_values(tmp_path):
    """What `ros2 param describe` and `ros2 param set` get from a node that reads its parameters
    at start-up (an int on the command line for a double is that double).
    """
    domain = new_domain_id()
    analyzer = NodeProcess('thrust_analyzer', domain, tmp_path, {'window_s': 2})
    probe = Probe(domain)
    try:
        described = probe.call(
            DescribeParameters,
            '/thrust_analyzer/describe_parameters',
            30.0,
            DescribeParameters.Request(names=['gamma', 'report_path']),
        )
        gamma, report_path = described.descriptors
        assert gamma.description == TABLES['thrust_analyzer']['gamma'].description
        assert gamma.type == ParameterType.PARAMETER_DOUBLE and gamma.read_only
        bounds = [(r.from_value, r.to_value) for r in gamma.floating_point_range]
        assert bounds == [(1.0, math.inf)]
        assert gamma.additional_constraints == '(1, inf)'
        assert report_path.type == ParameterType.PARAMETER_STRING and report_path.read_only
        change = Parameter('gamma', value=1.3).to_parameter_msg()
        result = probe.call(
            SetParameters,
            '/thrust_analyzer/set_parameters',
            30.0,
            SetParameters.Request(parameters=[change]),
        ).results[0]
        assert not result.successful and 'read-only' in result.reason, result
        values = probe.call(
            GetParameters,
            '/thrust_analyzer/get_parameters',
            30.0,
            GetParameters.Request(names=['gamma', 'window_s']),
        ).values
        assert [(v.type, v.double_value) for v in values] == [
            (ParameterType.PARAMETER_DOUBLE, 1.402),
            (ParameterType.PARAMETER_DOUBLE, 2.0),
        ]
        assert 'Traceback' not in analyzer.output()
    finally:
        probe.close()
        analyzer.stop()
