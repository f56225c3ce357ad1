"""The PlotJuggler and Foxglove layouts under config/ name only topics interfaces.md lists, and
fields those topics' message types have; each shows what it promises (raw bridges, the wrench
with its ±u band, the overload flag, /diagnostics); setup.py installs both.
"""

from __future__ import annotations

import json
from pathlib import Path
import re
import runpy
import xml.etree.ElementTree as ElementTree

import pytest
import setuptools

from balance_calib.bags.messages import typestore

ROOT = Path(__file__).resolve().parents[2]
INTERFACES = ROOT / 'docs' / 'interfaces.md'
PLOTJUGGLER = ROOT / 'config' / 'plotjuggler' / 'balance_live.xml'
FOXGLOVE = ROOT / 'config' / 'foxglove' / 'balance_live.json'
SCRIPT_TOPICS = '/studio_script/'  # Foxglove user scripts' own outputs
COMPONENTS = ('force/x', 'force/y', 'force/z', 'torque/x', 'torque/y', 'torque/z')


def interface_topics() -> dict[str, str]:
    """Topic -> message type, from interfaces.md's topic tables and its sentences
    "`/topic` (`pkg/msg/Type`".
    """
    text = INTERFACES.read_text()
    rows = re.findall(r'^\| `(/[a-z_/]+)` \| `([a-z_]+/msg/\w+)`', text, re.M)
    inline = re.findall(r'`(/[a-z_/]+)` \(`([a-z_]+/msg/\w+)`', text)
    return dict(rows + inline)


def has_field(msg_type: str, fields: list[str]) -> bool:
    """Does msg_type have the nested field path (rosbags' message definitions)?"""
    store = typestore()
    for index, name in enumerate(fields):
        definitions = dict(store.fielddefs[msg_type][1])
        if name not in definitions:
            return False
        kind, detail = definitions[name]
        if index == len(fields) - 1:
            return True
        if not isinstance(detail, str):  # a base type or an array: no deeper field
            return False
        msg_type = detail
    return True


def split_series(series: str, topics: dict[str, str]) -> tuple[str, list[str]]:
    """'/balance/raw/wrench/force/x' -> ('/balance/raw', ['wrench', 'force', 'x']): the longest
    interface topic the series starts with; ('', []) when none.
    """
    for topic in sorted(topics, key=len, reverse=True):
        if series.startswith(topic + '/'):
            return topic, series[len(topic) + 1 :].split('/')
    return '', []


def plotjuggler_series() -> tuple[set[str], set[str], dict[str, tuple[str, ...]]]:
    """(curves plotted, topics the subscriber selects, custom series -> their sources)."""
    root = ElementTree.parse(PLOTJUGGLER).getroot()
    curves = {c.get('name') for c in root.iter('curve')}
    selected = root.find(".//plugin[@ID='ROS2 Topic Subscriber']/selected_topics").get('value')
    custom = {
        s.get('name'): (
            s.findtext('linked_source'),
            *[v.text for v in s.find('additional_sources') or []],
        )
        for s in root.iter('snippet')
    }
    return curves, set(selected.split(';')), custom


def test_plotjuggler_layout_plots_interface_topics_and_the_band_of_each_component():
    topics = interface_topics()
    assert {'/balance/raw', '/balance/wrench', '/balance/overload', '/diagnostics'} <= set(topics)
    assert topics['/balance/wrench_uncertainty'] == 'geometry_msgs/msg/WrenchStamped'
    curves, selected, custom = plotjuggler_series()
    assert selected <= set(topics), selected - set(topics)
    sources = {source for sourced in custom.values() for source in sourced}
    for series in (curves - set(custom)) | sources:
        topic, fields = split_series(series, topics)
        assert topic in selected, series  # a topic of the contract, and subscribed
        if topic != '/diagnostics':  # its series are named after the statuses' keys
            assert has_field(topics[topic], fields), series
    for component in COMPONENTS:
        assert f'/balance/raw/wrench/{component}' in curves
        assert f'/balance/wrench/wrench/{component}' in curves
    bands = [s for s in custom.values() if s[1].startswith('/balance/wrench_uncertainty/')]
    assert len(bands) == 12 and all(name in curves for name in custom)  # ± u for six
    assert '/balance/overload/data' in curves
    assert any(c.startswith('/diagnostics/') for c in curves)


def foxglove_topics(layout: dict) -> tuple[set[str], set[str], set[str]]:
    """(message paths 'topic.field...', topics named otherwise, script outputs)."""
    paths, named = set(), set()
    for panel in layout['configById'].values():
        paths |= {p['value'] for p in panel.get('paths', [])}
        if 'path' in panel:
            paths.add(panel['path'])
        if 'topicToRender' in panel:
            named.add(panel['topicToRender'])
    outputs = set()
    for script in layout.get('userNodes', {}).values():
        source = script['sourceCode']
        inputs = re.search(r'inputs = \[([^\]]*)\]', source).group(1)
        named |= set(re.findall(r'"([^"]+)"', inputs))
        outputs |= set(re.findall(r'output = "([^"]+)"', source))
    return paths, named, outputs


def test_foxglove_layout_names_interface_topics_and_a_band_script_fed_by_them():
    topics = interface_topics()
    layout = json.loads(FOXGLOVE.read_text())
    paths, named, outputs = foxglove_topics(layout)
    assert outputs and all(o.startswith(SCRIPT_TOPICS) for o in outputs)
    for path in paths:
        topic, _, fields = path.partition('.')
        if topic in outputs:
            continue
        assert topic in topics, path
        assert has_field(topics[topic], fields.split('.')), path
    assert named <= set(topics), named - set(topics)
    assert {'/balance/wrench', '/balance/wrench_uncertainty', '/diagnostics'} <= named
    for component in COMPONENTS:
        dotted = component.replace('/', '.')
        assert f'/balance/raw.wrench.{dotted}' in paths
        assert f'/balance/wrench.wrench.{dotted}' in paths
        for side in ('lower', 'upper'):
            assert any(p.endswith(f'.{side}.{dotted}') for p in paths)
    assert '/balance/overload.data' in paths
    # every panel of the layout tree is configured, and every configured panel placed
    placed = set(re.findall(r'"(\w+![\w-]+)"', json.dumps(layout['layout'])))
    assert placed == set(layout['configById'])


def test_the_checks_can_fail_on_a_topic_or_field_outside_the_contract():
    topics = interface_topics()
    assert split_series('/balance/rawx/wrench/force/x', topics) == ('', [])
    assert not has_field('geometry_msgs/msg/WrenchStamped', ['wrench', 'force', 'w'])
    assert not has_field('std_msgs/msg/Bool', ['value'])
    assert has_field('std_msgs/msg/Bool', ['data'])


def test_setup_installs_both_layouts(monkeypatch):
    captured = {}
    monkeypatch.setattr(setuptools, 'setup', lambda **kwargs: captured.update(kwargs))
    monkeypatch.chdir(ROOT)
    runpy.run_path(str(ROOT / 'setup.py'))
    data_files = dict(captured['data_files'])
    assert data_files['share/balance_calib/config/plotjuggler'] == [
        'config/plotjuggler/balance_live.xml'
    ]
    assert data_files['share/balance_calib/config/foxglove'] == [
        'config/foxglove/balance_live.json'
    ]


@pytest.fixture(autouse=True)
def _contract_present():
    if not INTERFACES.exists():
        pytest.skip(f'{INTERFACES} not found')
