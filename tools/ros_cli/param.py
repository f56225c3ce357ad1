"""`ros param list|get|set|describe|dump NODE ...`: a running node's parameters through its
rcl_interfaces parameter services, as ros2 param does.
"""

from __future__ import annotations

from .errors import ToolError
from .session import node_name, Session
from .values import parameter_value_to_python, python_to_parameter_value, TYPE_NAMES


def param_list(args) -> int:
    from rcl_interfaces.srv import ListParameters

    with Session() as session:
        reply = session.call(
            ListParameters,
            f'{node_name(args.node)}/list_parameters',
            ListParameters.Request(),
            args.timeout,
        )
    for name in sorted(reply.result.names):
        print(f'  {name}')
    return 0


def _get(session, node: str, names, timeout: float):
    from rcl_interfaces.srv import GetParameters

    request = GetParameters.Request(names=list(names))
    return session.call(GetParameters, f'{node}/get_parameters', request, timeout).values


def param_get(args) -> int:
    with Session() as session:
        values = _get(session, node_name(args.node), [args.name], args.timeout)
    if not values or values[0].type == 0:
        raise ToolError(
            f'{node_name(args.node)} has no parameter {args.name!r}; see "ros param list '
            f'{args.node}"'
        )
    value = values[0]
    print(f'{TYPE_NAMES[value.type].capitalize()} value is: {parameter_value_to_python(value)}')
    return 0


def param_set(args) -> int:
    from rcl_interfaces.msg import Parameter
    from rcl_interfaces.srv import SetParameters

    node = node_name(args.node)
    with Session() as session:
        current = _get(session, node, [args.name], args.timeout)
        kind = current[0].type if current else 0
        value = python_to_parameter_value(args.value, kind, args.name)
        reply = session.call(
            SetParameters,
            f'{node}/set_parameters',
            SetParameters.Request(parameters=[Parameter(name=args.name, value=value)]),
            args.timeout,
        )
    result = reply.results[0]
    if not result.successful:
        raise ToolError(
            f'setting {args.name} on {node} failed: {result.reason or "refused by the node"}'
        )
    print('Set parameter successful')
    return 0


def param_describe(args) -> int:
    from rcl_interfaces.srv import DescribeParameters

    node = node_name(args.node)
    with Session() as session:
        reply = session.call(
            DescribeParameters,
            f'{node}/describe_parameters',
            DescribeParameters.Request(names=list(args.names)),
            args.timeout,
        )
    for name, descriptor in zip(args.names, reply.descriptors):
        if descriptor.type == 0:
            raise ToolError(f'{node} has no parameter {name!r}; see "ros param list {args.node}"')
        print(f'Parameter name: {name}')
        print(f'  Type: {TYPE_NAMES.get(descriptor.type, descriptor.type)}')
        if descriptor.description:
            print(f'  Description: {descriptor.description}')
        print('  Constraints:')
        if descriptor.read_only:
            print('    Read only: true')
        for bound in list(descriptor.floating_point_range) + list(descriptor.integer_range):
            print(f'    Min value: {bound.from_value}')
            print(f'    Max value: {bound.to_value}')
            if bound.step:
                print(f'    Step: {bound.step}')
        if descriptor.additional_constraints:
            print(f'    Additional constraints: {descriptor.additional_constraints}')
    return 0


def param_dump(args) -> int:
    """The node's parameters as a params file (`--params-file`), as ros2 param dump prints it:
    dotted names nested.
    """
    from rcl_interfaces.srv import ListParameters
    import yaml

    node = node_name(args.node)
    with Session() as session:
        names = sorted(
            session.call(
                ListParameters, f'{node}/list_parameters', ListParameters.Request(), args.timeout
            ).result.names
        )
        values = _get(session, node, names, args.timeout) if names else []
        if len(values) != len(names):  # rclpy answers nothing when one is unset: one by one
            values = [(_get(session, node, [name], args.timeout) or [None])[0] for name in names]
    tree: dict = {}
    for name, value in zip(names, values):
        if value is None or value.type == 0:
            continue  # not set (a string array without a default)
        *path, leaf = name.split('.')
        branch = tree
        for part in path:
            branch = branch.setdefault(part, {})
        branch[leaf] = parameter_value_to_python(value)
    print(
        yaml.safe_dump(
            {node: {'ros__parameters': tree}}, sort_keys=False, allow_unicode=True
        ).rstrip()
    )
    return 0
