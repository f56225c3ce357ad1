"""`balance-calib virtual-daq`: the simulated balance as a data acquisition device, so that the
whole graph runs without hardware: virtual device -> balance_daq -> balance_calibrator.

The run is bridge_publisher's (the same parameters: mode, balance, seed, effects, rate_hz ...,
given with -p NAME:=VALUE or a params file's bridge_publisher section); its raw samples leave
through the device (simulation/virtual_device.py), the rig's and the tunnel's topics over DDS
(nodes/virtual_daq.py). rclpy is imported only once the device is open, so --help answers at once.
"""

from __future__ import annotations

from pathlib import Path
import sys

import yaml

from .errors import CommandError

DEFAULT_PRESETS = {'serial': 'serial_counts', 'tcp': 'tcp_mvv', 'udp': 'netft_rdt'}
MODES = ('calibration', 'wind_on')


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'virtual-daq',
        help='play the simulated balance as a data acquisition device (pty, TCP or UDP) '
        'for balance_daq',
        description=(
            "Play bridge_publisher's simulated balance (the same truth, noise and effects; "
            'calibration or wind_on mode) as a data acquisition device in the format of a '
            'config/daq preset: on a pty (--transport serial: the path is printed, and linked '
            'from --device when given), on a TCP port (listening at --device host:port; every '
            'client gets text lines) or over UDP (--device host:port: with a preset that has a '
            "start_request, ATI Net F/T's RDT, it binds there and streams records to whoever "
            'sends the request; without, it sends datagrams to that address). The raw samples '
            'go only through the device; in calibration mode it also publishes '
            '/calibration/applied_load and /calibration/gravity as the loading rig would, and in '
            'wind_on mode /balance/truth, over ROS 2 (node name virtual_daq). Start balance_daq '
            'with the same preset and -p device:=ADDRESS.'
        ),
        epilog=(
            'Example: balance-calib virtual-daq --transport tcp --device 127.0.0.1:50010 '
            '--mode wind_on -p loop:=true   and   balance_daq --ros-args --params-file '
            'config/daq/tcp_mvv.yaml -p device:=127.0.0.1:50010. Exit status 0 when the run is '
            'done (-p exit_when_done:=true) or on Ctrl-C, 1 when the node cannot start, 2 on '
            'bad options.'
        ),
    )
    parser.add_argument(
        '--transport', choices=('serial', 'tcp', 'udp'), required=True, help='the device link'
    )
    parser.add_argument(
        '--device',
        metavar='ADDRESS',
        help='tcp, udp: host:port (port 0: any free one, printed); serial: a path to link to '
        'the pty (optional)',
    )
    parser.add_argument(
        '--format',
        metavar='FILE.yaml',
        help='a preset (config/daq/NAME.yaml, or NAME) whose balance_daq parameters say what a '
        'record holds (columns, units, counts_to_mv, excitation_v, framing, record_format, '
        'line_prefix, start_request); default by transport: '
        + ', '.join(f'{t} {p}' for t, p in DEFAULT_PRESETS.items()),
    )
    parser.add_argument(
        '--mode', choices=MODES, help="bridge_publisher's mode (default: its default, calibration)"
    )
    parser.add_argument(
        '--params-file',
        metavar='FILE',
        help='a ros__parameters file whose bridge_publisher section sets the run '
        '(e.g. config/graph_params.yaml)',
    )
    parser.add_argument(
        '-p',
        '--param',
        action='append',
        default=[],
        metavar='NAME:=VALUE',
        help='a bridge_publisher parameter (bridge_publisher --help lists them), e.g. '
        '-p rate_hz:=1000 -p seed:=3; after --params-file',
    )
    parser.set_defaults(func=run)


def format_path(transport: str, given: str | None) -> Path:
    from ..config import ConfigError, resolve_config_path

    name = given or f'daq/{DEFAULT_PRESETS[transport]}'
    path = Path(name)
    if path.exists():
        return path
    try:
        return resolve_config_path(name if '/' in name else f'daq/{name}')
    except ConfigError:
        raise CommandError(f'--format {name}: no such file, nor a preset of config/daq/') from None


def publisher_parameters(args) -> dict:
    """bridge_publisher parameters from --params-file, -p and --mode, in that order."""
    parameters: dict = {}
    if args.params_file:
        try:
            data = yaml.safe_load(Path(args.params_file).read_text()) or {}
            section = data.get('bridge_publisher', {}).get('ros__parameters', {})
        except (OSError, yaml.YAMLError, AttributeError) as err:
            raise CommandError(
                f'--params-file {args.params_file}: cannot read it: {err}'
            ) from None
        parameters.update(section)
    for item in args.param:
        name, sep, text = item.partition(':=')
        if not sep or not name:
            raise CommandError(f'-p {item!r}: expected NAME:=VALUE')
        try:
            parameters[name] = yaml.safe_load(text) if text else ''
        except yaml.YAMLError:
            raise CommandError(f'-p {item!r}: the value is not YAML') from None
    if args.mode:
        parameters['mode'] = args.mode
    for name, value in parameters.items():
        if value is None:
            raise CommandError(f'parameter {name}: no value')
    if parameters.get('mode', MODES[0]) not in MODES:
        raise CommandError(
            f'mode {parameters["mode"]!r}: virtual-daq plays {" or ".join(MODES)} '
            "(bridge_publisher's modes with a balance behind the bridges)"
        )
    return parameters


def run(args) -> int:
    from ..simulation.virtual_device import DeviceError, read_format, VirtualDevice

    parameters = publisher_parameters(args)
    path = format_path(args.transport, args.format)
    try:
        device = VirtualDevice(args.transport, args.device, read_format(path), str(path))
    except DeviceError as err:
        raise CommandError(str(err)) from None
    try:
        print(
            f'virtual-daq: {args.transport} device at {device.address}, format {path}',
            flush=True,
        )
        from ..nodes.virtual_daq import run as run_node

        return run_node(device, parameters)
    finally:
        device.close()
        if sys.stdout.isatty():
            print(f'virtual-daq: {device.samples_sent} samples sent')
