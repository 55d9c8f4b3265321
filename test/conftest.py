"""Test isolation for ROS (local discovery only, a domain id of this test run's own, an
rclpy Context per test) and the test markers.

Markers (registered in setup.cfg): ``ros`` (needs rclpy and DDS), ``e2e`` (starts processes:
nodes, the graph, ``asmonc run``), ``slow`` (over about a second). ``ros`` and ``e2e`` are set
here from what a test uses: the ROS fixtures, rclpy (in the test, its fixtures or the module
functions it calls), subprocesses. ``slow`` is set in the test files, or here (SLOW) for the
files listed there. ``make test-fast`` runs what has none of the three.
"""
import inspect
import itertools
import os
import re
import sys
from pathlib import Path

import pytest

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
# One domain per pytest process, so parallel or leftover runs never cross-talk.
os.environ.setdefault('ROS_DOMAIN_ID', str(10 + os.getpid() % 80))

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
SHARED = REPO.parent / 'shared'
BAGS = REPO / 'bags'
sys.path.insert(0, str(REPO))

_domains = itertools.count()


def next_domain_id() -> int:
    """A DDS domain for one test (102..230, spread by process id so parallel runs rarely
    meet; the ``ros`` fixture uses 1..100, the one shared by the whole run 10..89)."""
    return 102 + (os.getpid() * 7 + next(_domains)) % 129


@pytest.fixture
def ros_context():
    """A fresh rclpy Context on a domain of its own (`next_domain_id`), shut down after
    the test."""
    import rclpy

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=next_domain_id())
    yield ctx
    rclpy.try_shutdown(context=ctx)


# --- markers -------------------------------------------------------------------------------

#: tests over about a second (measured with --durations=0, one file at a time), for files
#: that carry no marks of their own: 'test_x.py' (all its tests) or 'test_x.py::test_y'
#: (that test, all its parameters)
SLOW: tuple[str, ...] = (
    'test_bench.py::test_bench_prints_both_methods_at_both_sizes',
    'test_campaign.py::test_one_walk_end_to_end_and_cached',
    'test_gait.py::test_compiled_filter_step_equals_the_numpy_path',
    'test_gait.py::test_fusion_beats_either_source_and_survives_dropouts',
    'test_gait.py::test_turning_and_uphill_keep_the_model',
    'test_gait_bags.py::test_bag_streams_agree_with_each_other',
    'test_gait_bags.py::test_fusion_on_the_bag',
    'test_gait_bags.py::test_the_command',
    'test_gait_real.py::test_walking_is_detected_inside_the_reference_bouts',
    'test_gpod.py::test_a_detection_of_weak_edges_has_the_confidence_of_its_weighted_pixels',
    'test_gpod.py::test_a_low_box_seen_by_one_silhouette_is_placed_along_the_face_the_image_shows',
    'test_gpod.py::test_a_noisy_camera_makes_no_obstacles_on_clear_pavement',
    'test_gpod.py::test_a_noisy_camera_standing_still_is_still',
    'test_gpod.py::test_a_post_and_a_box_in_a_row_make_no_report_nearer_than_either',
    'test_gpod.py::test_a_right_camera_with_its_own_gain_gives_no_phantom',
    'test_gpod.py::test_a_small_box_that_appears_is_not_averaged_with_the_ground_it_stands_on',
    'test_gpod.py::test_a_small_box_track_is_not_ended_by_its_own_lowest_rows',
    'test_gpod.py::test_a_vigorous_walker_frame_without_motion_does_not_leave_the_plane_off',
    'test_gpod.py::test_a_way_between_two_obstacles_is_left_open',
    'test_gpod.py::test_a_wrong_motion_does_not_take_the_plane_off_the_ground',
    'test_gpod.py::test_an_obstacle_walked_up_to_is_still_reported_once_its_foot_leaves_the_view',
    'test_gpod.py::test_candidate_and_link_kernels_equal_the_numpy_path',
    'test_gpod.py::test_corner_search_compiled_equals_numpy',
    'test_gpod.py::test_detector_outputs_equal_without_the_new_kernels',
    'test_gpod.py::test_excess_is_averaged_while_still_and_not_when_moving',
    'test_gpod.py::test_finds_a_step_down',
    'test_gpod.py::test_hanging_runs_compiled_equals_numpy',
    'test_gpod.py::test_initialises_then_tracks_the_ground',
    'test_gpod.py::test_no_obstacles_on_flat_ground',
    'test_gpod.py::test_plane_stays_on_the_ground_stood_on_before_a_step_down',
    'test_gpod.py::test_refit_follows_a_pitch_change',
    'test_gpod.py::test_sigma_threshold_from_the_initial_fit',
    'test_gpod.py::test_small_box_standing_still',
    'test_gpod.py::test_smooth_slabs_walked_on_without_motion_keep_the_plane_or_lose_it',
    'test_gpod.py::test_the_paving_beyond_a_kerb_down_is_no_obstacle',
    'test_gpod.py::test_the_plane_does_not_creep_onto_the_ground_beyond_a_kerb_down',
    'test_gpod.py::test_the_plane_predicted_through_the_motion_stays_on_the_ground_stood_on',
    'test_gpod.py::test_track_confidence_accumulates_over_views_not_over_still_frames',
    'test_gpod.py::test_two_bodies_closer_than_the_cluster_radius_are_reported_each',
    'test_gpod.py::test_wall_beside_the_path_is_reported_where_it_leaves_the_view',
    'test_gpod.py::test_wall_with_a_blank_middle_is_reported_at_its_nearest_point',
    'test_gpod.py::test_weakly_textured_ground_lowers_the_edge_threshold_to_find_the_plane',
    'test_plain_face.py::test_the_detector_reports_a_faint_wall_as_an_obstacle_not_unknown_ground',
    'test_safety_walks.py::test_walk_false_alarms_and_reports',
    'test_sim_scenes.py::test_markings_change_the_image_but_are_not_obstacles',
    'test_unseen_ground.py::test_a_lost_pair_keeps_what_the_ground_usually_shows',
    'test_unseen_ground.py::test_a_plain_wall_that_appears_ahead_is_reported_at_its_foot',
    'test_unseen_ground.py::test_only_a_confident_report_explains_the_unseen_ground',
)

#: fixtures that start rclpy
ROS_FIXTURES = {'ros_context', 'ros'}
_PROCESS = re.compile(r'\bsubprocess\.(run|Popen|call|check_call|check_output)\b|\bPopen\(')
_NAME = re.compile(r'\b[A-Za-z_]\w*\b')


def _from_rclpy(obj) -> bool:
    name = getattr(obj, '__name__', '') if inspect.ismodule(obj) else \
        getattr(obj, '__module__', '') or ''
    return name == 'rclpy' or name.startswith('rclpy.')


def _uses(func, module, cache: dict) -> tuple[bool, bool]:
    """(uses rclpy, starts a process): in `func`'s source or the source of the functions of
    `module` it names, transitively."""
    key = (module.__name__, getattr(func, '__qualname__', repr(func)))
    if key in cache:
        return cache[key]
    cache[key] = (False, False)              # cycles
    try:
        src = inspect.getsource(func)
    except (OSError, TypeError):
        return cache[key]
    ros = 'rclpy' in src
    proc = bool(_PROCESS.search(src))
    for name in set(_NAME.findall(src)):
        obj = module.__dict__.get(name)
        if obj is None or obj is func:
            continue
        if _from_rclpy(obj):
            ros = True
        elif inspect.isfunction(obj) and obj.__module__ == module.__name__:
            r, p = _uses(obj, module, cache)
            ros, proc = ros or r, proc or p
    cache[key] = (ros, proc)
    return ros, proc


def _fixture_funcs(item):
    """(function, module) of the fixtures of `item` defined in the test folder."""
    info = getattr(item, '_fixtureinfo', None)
    for defs in (info.name2fixturedefs.values() if info else ()):
        for d in defs:
            mod = sys.modules.get(getattr(d.func, '__module__', ''))
            if mod is not None and Path(getattr(mod, '__file__', '') or '/').parent == HERE:
                yield d.func, mod


def _is_slow(item) -> bool:
    name = item.path.name
    test = name + item.nodeid[item.nodeid.find('::'):] if '::' in item.nodeid else name
    return any(test == s or test.startswith((s + '::', s + '[')) for s in SLOW)


def _module_fixtures(item) -> set:
    """(module, name) of the test folder's fixtures shared by a module or by the whole
    run that `item` uses."""
    info = getattr(item, '_fixtureinfo', None)
    out = set()
    for name, defs in (info.name2fixturedefs.items() if info else ()):
        for d in defs:
            mod = sys.modules.get(getattr(d.func, '__module__', ''))
            if d.scope in ('module', 'session') and mod is not None and \
                    Path(getattr(mod, '__file__', '') or '/').parent == HERE:
                out.add((item.path, name))
    return out


def pytest_collection_modifyitems(config, items):
    cache: dict = {}
    for item in items:
        func = getattr(item, 'function', None)
        if func is None:
            continue
        ros, proc = _uses(func, item.module, cache)
        for fix, mod in _fixture_funcs(item):
            r, p = _uses(fix, mod, cache)
            ros, proc = ros or r, proc or p
        if ros or ROS_FIXTURES & set(item.fixturenames):
            item.add_marker(pytest.mark.ros)
        if proc:
            item.add_marker(pytest.mark.e2e)
        if _is_slow(item):
            item.add_marker(pytest.mark.slow)
    # a fixture shared by a slow test is paid by whichever of its tests runs first: all slow
    shared = set().union(*(_module_fixtures(i) for i in items if i.get_closest_marker('slow')))
    for item in items:
        if not item.get_closest_marker('slow') and _module_fixtures(item) & shared:
            item.add_marker(pytest.mark.slow)


def spin_until(executor, predicate, timeout=10.0, step=0.05):
    """Spin `executor` until `predicate()` is true or `timeout` s pass; return predicate()."""
    import time

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        executor.spin_once(timeout_sec=step)
    return bool(predicate())


def stereo_types():
    """The stereo input topics of the detector and egomotion nodes and their rclpy types,
    in (left image, right image, left info, right info) order."""
    from sensor_msgs.msg import CameraInfo, Image
    return {'/stereo/left/image_rect': Image, '/stereo/right/image_rect': Image,
            '/stereo/left/camera_info': CameraInfo, '/stereo/right/camera_info': CameraInfo}


def read_messages(bag, types):
    """{topic: [rclpy message, ...]} of a bag, for the topics in ``types`` (topic -> type)."""
    from rclpy.serialization import deserialize_message
    from rosbags.rosbag2 import Reader
    per_topic = {t: [] for t in types}
    with Reader(bag) as r:
        conns = [c for c in r.connections if c.topic in types]
        for c, _, raw in r.messages(connections=conns):
            per_topic[c.topic].append(deserialize_message(bytes(raw), types[c.topic]))
    return per_topic


def stereo_sender(probe):
    """Publishers of the stereo input topics on the ``probe`` node, and
    ``send(left, right, left_info, right_info)`` publishing one pair (infos first; the
    images alone when the infos are None)."""
    from asmonc_vision.nodes.common import IMAGE_QOS
    pubs = {t: probe.create_publisher(typ, t, IMAGE_QOS) for t, typ in stereo_types().items()}

    def send(left, right, linfo=None, rinfo=None):
        if linfo is not None:
            pubs['/stereo/left/camera_info'].publish(linfo)
        if rinfo is not None:
            pubs['/stereo/right/camera_info'].publish(rinfo)
        pubs['/stereo/left/image_rect'].publish(left)
        pubs['/stereo/right/image_rect'].publish(right)
    return pubs, send


def diagnostic_statuses(probe, name: str) -> list:
    """A list that fills with the DiagnosticStatus entries named ``name`` arriving on
    /diagnostics (subscribed on the ``probe`` node)."""
    from diagnostic_msgs.msg import DiagnosticArray

    out: list = []
    probe.create_subscription(
        DiagnosticArray, '/diagnostics',
        lambda m: out.extend(s for s in m.status if s.name == name), 10)
    return out


class RosGraph:
    """An rclpy Context on a domain of its own, a single-threaded executor, and the
    nodes added to it (destroyed at `close`). For node tests over real topics."""

    def __init__(self, domain_id: int, deadline: float = 15.0):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=domain_id)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.deadline = deadline
        self.nodes = []

    def add(self, node):
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def spin_until(self, pred, what, deadline=None, each=None, period=0.05):
        """Spin until pred(); call each() every `period` s meanwhile; fail after the
        deadline (a generous bound so a broken node fails the test instead of hanging it,
        not a speed test)."""
        import time

        end = time.monotonic() + (self.deadline if deadline is None else deadline)
        nxt = time.monotonic()
        while time.monotonic() < end:
            if each is not None and time.monotonic() >= nxt:
                each()
                nxt = time.monotonic() + period
            self.executor.spin_once(timeout_sec=0.01)
            if pred():
                return
        raise AssertionError(f'timed out waiting for {what}')

    def diagnostics(self, probe, name: str) -> list:
        """`diagnostic_statuses` of ``probe`` named ``name``."""
        return diagnostic_statuses(probe, name)

    def spin_for(self, seconds: float) -> None:
        import time

        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)

    def close(self) -> None:
        import rclpy

        for n in self.nodes:
            self.executor.remove_node(n)
            n.destroy_node()
        self.executor.shutdown()
        rclpy.try_shutdown(context=self.ctx)


@pytest.fixture
def ros(request):
    """A RosGraph on a domain id of the test module's own (its ROS_DOMAIN_OFFSET) and
    with its DEADLINE (s); 0..101 are safe DDS domain ids on Linux, 0 is avoided."""
    offset = getattr(request.module, 'ROS_DOMAIN_OFFSET', 0)
    graph = RosGraph(1 + (os.getpid() * 3 + offset) % 100,
                     getattr(request.module, 'DEADLINE', 15.0))
    yield graph
    graph.close()


def fault_timeline(out) -> str:
    """Where each FAULT on /alarms of the replay recorded in ``out`` came, for an
    assertion's message: its text, its receive time after the first /obstacles list and
    before the last one (s, the recorder's clock), and the lists received before it."""
    from asmonc_vision.io import bagio
    lists, faults = [], []
    for topic, t, m in bagio.read_messages(out, ['/obstacles', '/alarms']):
        if topic == '/obstacles':
            lists.append(t)
        elif int(m.level) == 4:
            faults.append((t, m.text))
    if not lists:
        return f'{len(faults)} FAULT(s), no /obstacles'
    first, last = min(lists), max(lists)
    return '; '.join(f'FAULT {text!r} at +{(t - first) / 1e9:.3f} s, '
                     f'{(last - t) / 1e9:.3f} s before the last list, after '
                     f'{sum(x <= t for x in lists)} of {len(lists)} lists (the newest '
                     f'{(t - max([x for x in lists if x <= t], default=t)) / 1e9:.3f} s before)'
                     for t, text in faults)
