"""The node graph, written down once: which nodes run, from which console script and
module, with which parameters file and remappings, and which input each needs.

`asmonc run` (cli/run.py) starts the processing nodes of `GRAPH` whose input the bag
holds; `launch/asmonc.launch.py` starts the same nodes for a full ROS install, fed by
the bag player (``bag:=...``) or by the stereo capture node (``live:=true``). A test
checks that every executable named here is a console script of setup.py.

To add a node, append one `GraphNode` to `GRAPH` (and its console script to setup.py's
``NODES``); both starters pick it up.
"""
from __future__ import annotations

import shutil
from dataclasses import dataclass, field

#: inputs a node may need: stereo images ('images'), the inclinometer ('imu'), or
#: nothing from the sensors ('none': started whenever any other node is)
NEEDS = ('images', 'imu', 'none')


@dataclass(frozen=True)
class GraphNode:
    """One node of the graph.

    Attributes:
        name: short name (log file, messages of `asmonc run`), e.g. 'detector'.
        executable: the console script (setup.py ``NODES`` key, `ros2 run` name).
        module: the Python module with ``main`` (started as ``python -m module``).
        ros_name: the node's ROS name.
        needs: the sensor input the node needs (one of `NEEDS`).
        outputs: topics it publishes that show it is up (and that `asmonc run` records).
        inputs: topics it subscribes that show it is connected. The node watches each
            (`nodes.common.watch_input_links`): `asmonc run` waits for the node to log the
            link of an input another node publishes before it starts the next node or
            the player, and of an input the bag feeds before the player plays.
        params_file: its file in config/ (``ros__parameters``, equal to the defaults).
        remappings: (from, to) topic remappings passed to the node.
        start_late: started after the others are connected (its start-up grace must not
            be used up while a detector compiles its kernels).
        respawn: restarted when it dies (by `asmonc run` and by the launch file).
        on_request: `asmonc run` starts it only when asked (the audio node, with
            ``--audio``); the launch file always starts it.
        nice: added to the process's niceness (Linux scheduling priority; 0 = as its
            starter): a node off the path from camera to ear runs lower, so that on a
            loaded or one-core machine it takes only the time that path leaves over.
    """

    name: str
    executable: str
    module: str
    ros_name: str
    needs: str
    outputs: tuple[str, ...]
    inputs: tuple[str, ...]
    params_file: str
    remappings: tuple[tuple[str, str], ...] = ()
    start_late: bool = False
    respawn: bool = True
    on_request: bool = False
    nice: int = 0

    def __post_init__(self) -> None:
        if self.needs not in NEEDS:
            raise ValueError(f'GraphNode {self.name}: needs must be one of {NEEDS}, '
                             f'got {self.needs!r}')
        if not 0 <= self.nice <= 19:
            raise ValueError(f'GraphNode {self.name}: nice must be in [0, 19], '
                             f'got {self.nice!r}')

    def command_prefix(self) -> list[str]:
        """The words put before the node's command: ``nice -n N`` for a lowered
        priority (where the ``nice`` program exists), else none."""
        if self.nice and shutil.which('nice'):
            return ['nice', '-n', str(self.nice)]
        return []

    def ros_args(self) -> list[str]:
        """Command-line ROS arguments for the remappings (``-r from:=to`` each)."""
        out: list[str] = []
        for a, b in self.remappings:
            out += ['-r', f'{a}:={b}']
        return out


LEFT_IMAGE = '/stereo/left/image_rect'
RIGHT_IMAGE = '/stereo/right/image_rect'
IMU = '/inclinometer/imu'

#: the processing graph, in start order (nodes with ``start_late`` go last, in this order)
GRAPH: tuple[GraphNode, ...] = (
    GraphNode('detector', 'detector_node', 'asmonc_vision.nodes.detector_node',
              'detector_node', 'images', ('/obstacles',), (LEFT_IMAGE, RIGHT_IMAGE),
              'detector.yaml'),
    # the egomotion node is off the path from camera to ear (the detector does not wait
    # for it; the alarm node smooths the walking speed over its motions): it runs lower
    GraphNode('egomotion', 'egomotion_node', 'asmonc_vision.nodes.egomotion_node',
              'egomotion_node', 'images', ('/egomotion',), (LEFT_IMAGE,), 'egomotion.yaml',
              nice=10),
    # the walk model's state changes at the pace of steps, not frames: it yields too
    GraphNode('gait', 'gait_filter_node', 'asmonc_vision.nodes.gait_node',
              'gait_filter_node', 'imu', ('/gait/state',), (IMU,), 'gait_filter.yaml',
              start_late=True, nice=5),
    GraphNode('alarm', 'alarm_node', 'asmonc_vision.nodes.alarm_node', 'alarm_node',
              'images', ('/alarms',), ('/obstacles',), 'alarm.yaml', start_late=True),
    GraphNode('audio', 'audio_node', 'asmonc_vision.nodes.audio_node', 'audio_node',
              'images', (), ('/alarms', '/stereo/left/camera_info'), 'audio.yaml',
              start_late=True, on_request=True),
)


@dataclass(frozen=True)
class SourceNode:
    """A node that feeds the graph: the bag player, or a live sensor driver."""

    name: str
    executable: str
    module: str
    ros_name: str
    params_file: str
    respawn: bool = False
    remappings: tuple[tuple[str, str], ...] = field(default=())


#: where the sensor data come from: a bag (`asmonc run`, ``bag:=``), or the cameras and
#: the serial inclinometer (``live:=true``)
SOURCES: dict[str, tuple[SourceNode, ...]] = {
    'bag': (SourceNode('player', 'bag_player_node', 'asmonc_vision.nodes.player_node',
                       'bag_player_node', 'bag_player.yaml'),),
    'live': (SourceNode('capture', 'stereo_capture_node', 'asmonc_vision.nodes.capture_node',
                        'stereo_capture_node', 'stereo_capture.yaml', respawn=True),
             SourceNode('compass', 'compass_node', 'asmonc_vision.nodes.compass_node',
                        'compass_node', 'compass.yaml', respawn=True)),
}
#: seconds a launch file waits before it restarts a node that died
RESPAWN_DELAY = 1.0


def nodes_for(inputs: set[str] | frozenset[str],
              requested: set[str] | frozenset[str] = frozenset()) -> list[GraphNode]:
    """The nodes of `GRAPH` the given sensor inputs call for, in start order: those that
    need one of ``inputs`` (an ``on_request`` node only when its name is in
    ``requested``), and those that need none when any does."""
    chosen = [n for n in GRAPH if n.needs in inputs
              and (not n.on_request or n.name in requested)]
    if chosen:
        chosen += [n for n in GRAPH if n.needs == 'none']
    early = [n for n in GRAPH if n in chosen and not n.start_late]
    late = [n for n in GRAPH if n in chosen and n.start_late]
    return early + late


def by_name(name: str) -> GraphNode:
    """The `GRAPH` node called ``name`` (KeyError if none)."""
    for n in GRAPH:
        if n.name == name:
            return n
    raise KeyError(name)


def executables() -> set[str]:
    """Every console script the graph and its sources run."""
    return {n.executable for n in GRAPH} | {s.executable for src in SOURCES.values()
                                            for s in src}


def launch_entries(source: str, config_dir: str, bag: str = '', rate: float = 1.0,
                   params_files: tuple[str, ...] = ()) -> list[dict]:
    """The nodes a launch file starts, as keyword arguments of ``launch_ros.actions.Node``
    (``package``, ``executable``, ``name``, ``parameters``, ``remappings``, ``respawn``,
    ``respawn_delay``, ``output``; ``prefix`` for a node with a ``nice``): the sources of
    ``source`` ('bag' or 'live'), then every node of `GRAPH` (all of them: a live rig has
    cameras and an inclinometer).

    Args:
        source: a key of `SOURCES`.
        config_dir: the installed config/ directory (each node's ``params_file`` in it).
        bag: the bag to play (``source`` 'bag').
        rate: the replay rate (``source`` 'bag').
        params_files: more ``ros__parameters`` files for every node, applied after its own.
    Raises:
        ValueError: an unknown source, or 'bag' without a bag.
    """
    if source not in SOURCES:
        raise ValueError(f"unknown source {source!r}; one of {', '.join(SOURCES)}")
    if source == 'bag' and not bag:
        raise ValueError('a bag to play is needed (bag:=PATH), or live:=true')
    out = []
    for n in (*SOURCES[source], *nodes_for(set(NEEDS), {g.name for g in GRAPH})):
        params: list = [f'{config_dir}/{n.params_file}', *params_files]
        if n.executable == 'bag_player_node':
            params.append({'bag': bag, 'rate': float(rate)})
        entry = dict(package='asmonc_vision', executable=n.executable, name=n.ros_name,
                     parameters=params, remappings=list(n.remappings),
                     respawn=n.respawn, respawn_delay=RESPAWN_DELAY, output='screen')
        prefix = n.command_prefix() if isinstance(n, GraphNode) else []
        if prefix:
            entry['prefix'] = ' '.join(prefix)
        out.append(entry)
    return out
