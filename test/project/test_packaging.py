"""ROS packaging: launch/graph.launch.yaml starts what launchless_scripts/graph starts, with
parameters the nodes declare; setup.py installs config/models and the launch file; package.xml
names a checked key for every third-party import (no DDS, no build: launchless_scripts/colcon_check
builds for real).
"""

import ast
from pathlib import Path
import re
import runpy
import sys
import xml.etree.ElementTree as ElementTree

import pytest
import yaml

from balance_calib.nodes import _help

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / 'launch' / 'graph.launch.yaml'
GRAPH = ROOT / 'launchless_scripts' / 'graph'

# Keys checked by hand against ros/rosdistro at 8468e88ccd52 (2026-08-22): ROS 2 Jazzy packages
# in jazzy/distribution.yaml, rosdep keys in rosdep/python.yaml. Check a new key there first.
JAZZY_PACKAGES = {
    'rclpy',
    'rcl_interfaces',
    'ament_index_python',
    'geometry_msgs',
    'sensor_msgs',
    'std_msgs',
    'std_srvs',
    'diagnostic_msgs',
    'launch_ros',
    'launch_yaml',
}
ROSDEP_KEYS = {
    'python3-numpy',
    'python3-scipy',
    'python3-yaml',
    'python3-matplotlib',
    'python3-pytest',
    'python3-hypothesis',
    'python3-rosbags-pip',
    'mcap-ros2-support',
    'python3-setuptools',
    'python3-pil',
    'python3-serial',
}
# import name -> the key that installs it (zstandard and lz4 come with mcap, mcap with
# mcap-ros2-support)
IMPORTS = {
    'numpy': 'python3-numpy',
    'scipy': 'python3-scipy',
    'yaml': 'python3-yaml',
    'matplotlib': 'python3-matplotlib',
    'rosbags': 'python3-rosbags-pip',
    'mcap': 'mcap-ros2-support',
    'mcap_ros2': 'mcap-ros2-support',
    'zstandard': 'mcap-ros2-support',
    'lz4': 'mcap-ros2-support',
    'pytest': 'python3-pytest',
    'hypothesis': 'python3-hypothesis',
    'setuptools': 'python3-setuptools',
    'PIL': 'python3-pil',
    'serial': 'python3-serial',
    **{name: name for name in JAZZY_PACKAGES},
}


def console_scripts() -> dict[str, str]:
    """setup.py's console scripts: name -> module (read from the file, not from an install)."""
    tree = ast.parse((ROOT / 'setup.py').read_text())
    call = next(
        n
        for n in ast.walk(tree)
        if isinstance(n, ast.Call) and getattr(n.func, 'id', '') == 'setup'
    )
    entry_points = ast.literal_eval(
        next(k.value for k in call.keywords if k.arg == 'entry_points')
    )
    return dict(
        (part.strip() for part in line.split('=')) for line in entry_points['console_scripts']
    )


def setup_keywords(monkeypatch) -> dict:
    """What setup.py passes to setuptools.setup(), run in the source tree, building nothing."""
    import setuptools

    captured = {}
    monkeypatch.setattr(setuptools, 'setup', lambda **kwargs: captured.update(kwargs))
    monkeypatch.chdir(ROOT)
    runpy.run_path(str(ROOT / 'setup.py'))
    return captured


def launch_entities() -> tuple[dict, list[dict]]:
    entries = yaml.safe_load(LAUNCH.read_text())['launch']
    assert all(len(entry) == 1 for entry in entries), entries
    args = {e['arg']['name']: e['arg'] for e in entries if 'arg' in e}
    nodes = [e['node'] for e in entries if 'node' in e]
    assert len(args) + len(nodes) == len(entries), 'only arg and node entries are expected'
    return args, nodes


def graph_nodes() -> list[str]:
    """The executables launchless_scripts/graph starts (its `nodes` list and what it appends)."""
    text = GRAPH.read_text()
    listed = re.search(r'^nodes = \[([^\]]*)\]', text, re.M).group(1)
    return (
        re.findall(r'"(\w+)"', listed)
        + re.findall(r'nodes\.append\("(\w+)"\)', text)
        + re.findall(r'nodes\[0\] = "(\w+)"', text)  # --daq: in place of bridge_publisher
    )


def declared_parameters(executable: str) -> set[str]:
    module = sys.modules.get(console_scripts()[executable].split(':')[0]) or __import__(
        console_scripts()[executable].split(':')[0], fromlist=['main']
    )
    return {name for name, _, _ in _help.parameter_table(module)}


def test_launch_file_starts_the_graphs_nodes_with_parameters_they_declare():
    args, nodes = launch_entities()
    scripts = console_scripts()
    executables = [node['exec'] for node in nodes]
    assert (
        set(executables)
        == set(graph_nodes())
        == {'bridge_publisher', 'balance_calibrator', 'balance_recorder', 'balance_daq'}
    )
    for node in nodes:
        assert node['pkg'] == 'balance_calib' and node['exec'] in scripts, node
        assert node['name'] == node['exec']  # as the graph runs them: the params file's sections
        assert (
            'remap' not in node and 'ros_args' not in node and 'args' not in node
        )  # the graph has none
        files = [p['from'] for p in node['param'] if 'from' in p]
        # balance_daq reads its device's preset (config/daq), the others the graph's file
        wanted = '$(var daq_params)' if node['exec'] == 'balance_daq' else '$(var params_file)'
        assert files == [wanted], node
        inline = {p['name'] for p in node['param'] if 'name' in p}
        assert inline <= declared_parameters(node['exec']), (node['exec'], inline)
        used = set(re.findall(r'\$\(var (\w+)\)', yaml.safe_dump(node)))
        assert used <= set(args), (node['exec'], used - set(args))
        assert set(node) <= {
            'pkg',
            'exec',
            'name',
            'output',
            'param',
            'if',
            'unless',
            'on_exit',
        }, node
    # a bridge_publisher for either value of stop_with_campaign, exactly one of them shutting
    # down, both only without daq_params; balance_daq only with it
    publishers = [n for n in nodes if n['exec'] == 'bridge_publisher']
    no_daq = "'$(var daq_params)' == ''"
    assert sorted((n['if'], n.get('on_exit')) for n in publishers) == [
        (f"""$(eval "'$(var stop_with_campaign)' != 'true' and {no_daq}")""", None),
        (f"""$(eval "'$(var stop_with_campaign)' == 'true' and {no_daq}")""", 'shutdown'),
    ]
    (daq,) = [n for n in nodes if n['exec'] == 'balance_daq']
    assert daq['unless'] == f'$(eval "{no_daq}")' and 'if' not in daq
    assert args['daq_params']['default'] == ''
    # the same parameters file as the graph's default, from where setup.py installs it
    assert (
        args['params_file']['default']
        == '$(find-pkg-share balance_calib)/config/graph_params.yaml'
    )
    assert 'default=str(root / "config" / "graph_params.yaml")' in GRAPH.read_text()


def test_every_parameter_of_the_shipped_params_file_is_declared_by_its_node():
    params = yaml.safe_load((ROOT / 'config' / 'graph_params.yaml').read_text())
    scripts = console_scripts()
    assert set(params) <= set(scripts), sorted(set(params) - set(scripts))
    for node, section in params.items():
        given = set(section['ros__parameters'])
        unknown = given - declared_parameters(node)
        assert unknown == set(), (node, sorted(unknown))


def test_declared_parameters_are_read_from_the_nodes_own_tables():
    """The check above can fail: the tables are the nodes', and a made-up name is not in them."""
    from balance_calib.live.parameters import PARAMETERS as CALIBRATOR
    from balance_calib.nodes.bridge_publisher import PARAMETERS as PUBLISHER

    assert declared_parameters('balance_calibrator') == set(CALIBRATOR)
    assert declared_parameters('bridge_publisher') == set(PUBLISHER)
    assert declared_parameters('balance_recorder') == {'topics', 'output'}
    assert 'overload_fractoin' not in declared_parameters('balance_calibrator')


def test_setup_installs_config_models_and_the_launch_file(monkeypatch):
    data_files = dict(setup_keywords(monkeypatch)['data_files'])
    models = sorted(
        p.relative_to(ROOT).as_posix() for p in (ROOT / 'config' / 'models').glob('*.yaml')
    )
    assert len(models) >= 2
    assert sorted(data_files['share/balance_calib/config/models']) == models
    assert data_files['share/balance_calib/launch'] == ['launch/graph.launch.yaml']
    assert 'config/graph_params.yaml' in data_files['share/balance_calib/config']
    presets = sorted(
        p.relative_to(ROOT).as_posix() for p in (ROOT / 'config' / 'daq').glob('*.yaml')
    )
    assert len(presets) == 3 and sorted(data_files['share/balance_calib/config/daq']) == presets


def test_an_installed_package_finds_its_models_in_its_share_directory(tmp_path, monkeypatch):
    """Installed without --symlink-install the package has no config/ beside it: share/ it is."""
    from balance_calib.aero.model_file import load_model
    import balance_calib.config as config

    share = tmp_path / 'prefix' / 'share'
    (share / 'ament_index' / 'resource_index' / 'packages').mkdir(parents=True)
    (share / 'ament_index' / 'resource_index' / 'packages' / 'balance_calib').write_text('')
    (share / 'balance_calib' / 'config' / 'models').mkdir(parents=True)
    shipped = ROOT / 'config' / 'models' / 'euler_replica_lmc6522.yaml'
    (share / 'balance_calib' / 'config' / 'models' / shipped.name).write_text(shipped.read_text())
    (share / 'balance_calib' / 'config' / 'lmc6522.yaml').write_text(
        (ROOT / 'config' / 'lmc6522.yaml').read_text()
    )
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path / 'prefix'))
    monkeypatch.setattr(config, 'CONFIG_DIR', tmp_path / 'site-packages' / 'config')  # not there
    model = load_model('euler_replica_lmc6522')
    assert Path(model.path).parent == share / 'balance_calib' / 'config' / 'models'
    assert (
        config.resolve_config_path('lmc6522')
        == share / 'balance_calib' / 'config' / 'lmc6522.yaml'
    )
    with pytest.raises(config.ConfigError, match='no such model file'):
        load_model('no_such_model')


def _third_party_imports(directory: Path, local: set[str]) -> dict[str, str]:
    """Top-level imported names, neither the standard library nor ours -> a file using it."""
    found = {}
    for path in sorted(directory.rglob('*.py')):
        for node in ast.walk(ast.parse(path.read_text())):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else (
                    [node.module]
                    if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module
                    else []
                )
            )
            for name in names:
                top = name.split('.')[0]
                if top not in sys.stdlib_module_names and top not in local:
                    found.setdefault(top, str(path.relative_to(ROOT)))
    return found


def test_setup_installs_balance_calib_and_not_the_development_tools(monkeypatch):
    packages = setup_keywords(monkeypatch)['packages']
    on_disk = {
        '.'.join(p.parent.relative_to(ROOT).parts)
        for p in (ROOT / 'balance_calib').rglob('__init__.py')
    }
    assert set(packages) == on_disk and 'balance_calib.launchless' in packages
    # tools/ros_cli (launchless_scripts/ros, the stand-in for ros2cli) is a package, not shipped
    assert (ROOT / 'tools' / 'ros_cli' / '__init__.py').exists()
    assert not [p for p in packages if not p.startswith('balance_calib')], packages


def test_package_xml_names_a_checked_key_for_every_import():
    package = ElementTree.parse(ROOT / 'package.xml').getroot()
    run = {
        e.text for tag in ('exec_depend', 'depend', 'buildtool_depend') for e in package.iter(tag)
    }
    test = {e.text for e in package.iter('test_depend')}
    assert (run | test) <= JAZZY_PACKAGES | ROSDEP_KEYS, sorted(
        (run | test) - JAZZY_PACKAGES - ROSDEP_KEYS
    )
    # the old, unverified keys are gone
    assert not {'python3-rosbags', 'python3-mcap', 'python3-mcap-ros2-support'} & (run | test)
    for directory, keys in (
        (ROOT / 'balance_calib', run),
        (ROOT / 'tools' / 'ros_cli', run),  # launchless_scripts/ros runs in the package's venv
        (ROOT / 'test', run | test),
    ):
        local = {'balance_calib', 'ros_cli'} | {p.stem for p in (ROOT / 'test').rglob('*.py')}
        for name, where in _third_party_imports(directory, local).items():
            assert name in IMPORTS, f'{where} imports {name}: which rosdep key installs it?'
            assert IMPORTS[name] in keys, (
                f'{where} imports {name}; package.xml lacks {IMPORTS[name]}'
            )
