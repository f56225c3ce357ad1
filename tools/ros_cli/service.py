"""`ros service list|call`: the services on the graph, a call of a std_srvs Trigger or Empty."""

from __future__ import annotations

from .errors import ToolError
from .session import other_nodes, own_name, rosout_nodes, Session, settled


def service_list(args) -> int:
    with Session() as session:
        own = own_name(session) + '/'
        services = settled(
            session,
            lambda: sorted(
                (name, types)
                for name, types in session.node.get_service_names_and_types()
                if not name.startswith(own)
            ),
            args.timeout,
            complete=lambda listing: _every_node_listed(session, listing),
        )
    for name, types in services:
        print(f'{name} [{", ".join(types)}]')
    return 0


# what every rclpy node serves (unless started without parameter services)
PARAMETER_SERVICES = (
    'describe_parameters',
    'get_parameter_types',
    'get_parameters',
    'list_parameters',
    'set_parameters',
    'set_parameters_atomically',
)


def _every_node_listed(session, services) -> bool:
    """Every other node on the graph has all its parameter services in the listing: DDS brings a
    node's service servers one by one, so a node with only some of them is not yet the whole
    picture (a node without parameter services makes the listing wait for --timeout).
    """
    names = {name for name, _ in services}
    nodes = set(other_nodes(session)) | rosout_nodes(session)
    return all(f'{node}/{service}' in names for node in nodes for service in PARAMETER_SERVICES)


def service_call(args) -> int:
    if args.type not in ('std_srvs/srv/Trigger', 'std_srvs/srv/Empty'):
        raise ToolError(
            f'service type {args.type}: only std_srvs/srv/Trigger and std_srvs/srv/Empty are '
            'supported'
        )
    from std_srvs.srv import Empty, Trigger

    service_type = Trigger if args.type.endswith('Trigger') else Empty
    with Session() as session:
        reply = session.call(service_type, args.service, service_type.Request(), args.timeout)
    if service_type is Empty:
        print('response: (empty)')
        return 0
    print(f'success: {str(reply.success).lower()}\nmessage: {reply.message}')
    return 0 if reply.success else 1
