"""The graph description (asmonc_vision/graph.py) against setup.py, config/ and the
launch file."""
from __future__ import annotations

import ast
import importlib
import importlib.util
from pathlib import Path

import pytest
import yaml

from asmonc_vision import graph

ROOT = Path(__file__).resolve().parent.parent


def _setup_dict(name: str) -> dict:
    """A dict literal assigned at the top of setup.py (setup.py runs setup() on import)."""
    tree = ast.parse((ROOT / 'setup.py').read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, 'id', None) == name
                                                for t in node.targets):
            return ast.literal_eval(node.value)
    raise AssertionError(f'setup.py has no {name}')


def _all_nodes():
    return [*graph.GRAPH, *(s for src in graph.SOURCES.values() for s in src)]


def test_every_node_of_the_graph_is_a_console_script_of_setup_py():
    scripts = _setup_dict('NODES')
    for n in _all_nodes():
        assert n.executable in scripts, f'{n.executable} is not in setup.py NODES'
        assert scripts[n.executable] == f'{n.module}:main'
    # and every node script of setup.py is started by the graph or its sources, except
    # the recorder, which `asmonc run` runs in its own process for --out
    assert set(scripts) - graph.executables() == {'bag_recorder_node'}


@pytest.mark.parametrize('n', _all_nodes(), ids=lambda n: n.name)
def test_each_node_has_its_module_main_and_params_file(n):
    assert importlib.util.find_spec(n.module) is not None
    assert callable(importlib.import_module(n.module).main)
    doc = yaml.safe_load((ROOT / 'config' / n.params_file).read_text())
    assert list(doc) == [n.ros_name] and 'ros__parameters' in doc[n.ros_name]


def test_node_names_are_unique_and_needs_known():
    names = [n.name for n in _all_nodes()]
    assert len(names) == len(set(names))
    assert len({n.ros_name for n in _all_nodes()}) == len(names)
    with pytest.raises(ValueError, match='needs'):
        graph.GraphNode('x', 'x', 'x', 'x', 'camera', (), (), 'x.yaml')


def test_nodes_for_picks_by_input_and_starts_late_nodes_last():
    images = graph.nodes_for({'images'})
    assert [n.name for n in images] == ['detector', 'egomotion', 'alarm']
    assert [n.name for n in graph.nodes_for({'imu'})] == ['gait']
    both = [n.name for n in graph.nodes_for({'images', 'imu'})]
    assert both == ['detector', 'egomotion', 'gait', 'alarm']
    assert graph.nodes_for(set()) == []
    # the audio node only when asked (asmonc run --audio), after the alarm node
    asked = [n.name for n in graph.nodes_for({'images'}, {'audio'})]
    assert asked == ['detector', 'egomotion', 'alarm', 'audio']
    assert [n.name for n in graph.nodes_for({'imu'}, {'audio'})] == ['gait']
    assert graph.by_name('alarm').start_late and not graph.by_name('detector').start_late
    with pytest.raises(KeyError):
        graph.by_name('nope')


def test_remappings_become_ros_args():
    n = graph.GraphNode('x', 'x', 'x', 'x', 'images', (), (), 'x.yaml',
                        remappings=(('/a', '/b'), ('/c', '/d')))
    assert n.ros_args() == ['-r', '/a:=/b', '-r', '/c:=/d']


def test_launch_entries_bag_and_live():
    bag = graph.launch_entries('bag', '/cfg', bag='/bags/x', rate=2.0,
                               params_files=('/over.yaml',))
    names = [e['name'] for e in bag]
    assert names == ['bag_player_node', 'detector_node', 'egomotion_node',
                     'gait_filter_node', 'alarm_node', 'audio_node']
    player = bag[0]
    assert player['parameters'] == ['/cfg/bag_player.yaml', '/over.yaml',
                                    {'bag': '/bags/x', 'rate': 2.0}]
    assert not player['respawn']            # a replay that ended is not restarted
    assert all(e['respawn'] and e['respawn_delay'] > 0 for e in bag[1:])
    assert bag[1]['parameters'] == ['/cfg/detector.yaml', '/over.yaml']
    live = [e['name'] for e in graph.launch_entries('live', '/cfg')]
    assert live[:2] == ['stereo_capture_node', 'compass_node'] and 'bag_player_node' not in live
    with pytest.raises(ValueError, match='bag'):
        graph.launch_entries('bag', '/cfg')
    with pytest.raises(ValueError, match='unknown source'):
        graph.launch_entries('usb', '/cfg')


def test_setup_installs_the_launch_file_and_package_xml_depends_on_launch_ros():
    assert (ROOT / 'launch' / 'asmonc.launch.py').is_file()
    assert "glob('launch/*.launch.py')" in (ROOT / 'setup.py').read_text()
    assert '<exec_depend>launch_ros</exec_depend>' in (ROOT / 'package.xml').read_text()


def test_asmonc_run_starts_the_graph_nodes():
    from asmonc_vision.replay import session
    assert session.GraphNode is graph.GraphNode
    assert 'nodes_for' in Path(session.__file__).read_text()


def test_launch_file_builds_the_graph(monkeypatch, tmp_path):
    pytest.importorskip('launch_ros')
    from launch import LaunchContext
    from launch_ros.actions import Node

    import ament_index_python.packages as aip
    monkeypatch.setattr(aip, 'get_package_share_directory', lambda pkg: str(tmp_path))
    spec = importlib.util.spec_from_file_location('asmonc_launch',
                                                  ROOT / 'launch' / 'asmonc.launch.py')
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    monkeypatch.setattr(mod, 'get_package_share_directory', lambda pkg: str(tmp_path))
    ld = mod.generate_launch_description()
    ctx = LaunchContext()
    for a in ld.entities[:-1]:
        a.visit(ctx)
    ctx.launch_configurations['bag'] = '/bags/x'
    nodes = ld.entities[-1].execute(ctx)
    assert all(isinstance(n, Node) for n in nodes)
    assert len(nodes) == 1 + len(graph.GRAPH)


def test_nodes_off_the_path_to_the_ear_run_at_a_lower_priority():
    """The egomotion node (the detector does not wait for it) and the walk model are
    started under ``nice`` by both starters; the detector, alarm and audio nodes are not."""
    entries = {e['name']: e for e in graph.launch_entries('bag', '/cfg', bag='/b')}
    assert entries['egomotion_node']['prefix'] == 'nice -n 10'
    assert entries['gait_filter_node']['prefix'] == 'nice -n 5'
    for name in ('detector_node', 'alarm_node', 'audio_node', 'bag_player_node'):
        assert 'prefix' not in entries[name], name
    assert graph.by_name('egomotion').command_prefix() == ['nice', '-n', '10']
    assert graph.by_name('detector').command_prefix() == []
    with pytest.raises(ValueError, match='nice must be in'):
        graph.GraphNode('x', 'x', 'x', 'x', 'images', (), (), 'x.yaml', nice=25)


_AUTOGROUP = Path('/proc/self/autogroup')
_SHOW = ('import sys; from asmonc_vision.nodes.common import share_cpu_by_nice; '
         'print(share_cpu_by_nice()); print(open("/proc/self/autogroup").read())')


@pytest.mark.skipif(not _AUTOGROUP.exists(), reason='no autogroup scheduling (not Linux)')
@pytest.mark.parametrize('own_session', [True, False])
def test_a_niced_node_in_a_session_of_its_own_gives_its_autogroup_its_nice(own_session):
    """With autogroups the kernel shares a CPU between sessions first: a niced node that
    leads its own session sets its autogroup's nice to its own (else it would take a whole
    session's share); one in the graph's session leaves the shared autogroup alone. The
    graph's starter keeps its children in its session (process groups of their own)."""
    import subprocess
    import sys
    out = subprocess.run(['nice', '-n', '7', sys.executable, '-c', _SHOW], capture_output=True,
                         text=True, check=True, start_new_session=own_session).stdout.split('\n')
    parent = _AUTOGROUP.read_text().split()
    if own_session:
        if out[0] == 'False':
            pytest.skip('this kernel or container refuses autogroup nice values')
        assert out[1].split()[-1] == '7', out
    else:
        assert out[0] == 'False' and out[1].split() == parent, out
    import inspect
    from asmonc_vision.replay import children
    src = inspect.getsource(children.Child.__init__)
    assert 'process_group=0' in src and 'start_new_session' not in src
