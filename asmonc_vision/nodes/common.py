"""What every asmonc_vision node shares: parameters from settings dataclasses, QoS
profiles, diagnostics and the Jazzy main loop.

Nodes stay thin: they declare their settings dataclass with `declare_config`, convert
messages once (see `conversions`), call the core, and publish.
"""
from __future__ import annotations

import contextlib
import dataclasses
import os
import signal
import threading
from typing import Any, Callable, TypeVar

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType, SetParametersResult)
from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                              ParameterUninitializedException)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)

from asmonc_vision.core.config import flat_fields, flat_values, override

T = TypeVar('T')

#: Large images: RELIABLE so that a replay loses no frame; shallow so a slow reader
#: gets the newest frames rather than an ever-growing backlog.
IMAGE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
#: Small sensor streams (inclinometer): best effort, as sensors publish.
SENSOR_QOS = qos_profile_sensor_data
#: Detector outputs: reliable, volatile.
RESULT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
#: Alarms: reliable and latched with depth 1, so a late subscriber (the speech output)
#: hears the current state at once, and never a backlog of stale alarms.
ALARM_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _descriptor(f: dataclasses.Field) -> ParameterDescriptor:
    md = f.metadata
    desc = ParameterDescriptor(description=md.get('description', ''),
                               read_only=bool(md.get('read_only', False)))
    if 'range' in md:
        lo, hi = md['range']
        if isinstance(f.default, int) and not isinstance(f.default, bool):
            desc.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
        else:
            desc.floating_point_range = [
                FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
    if 'choices' in md:
        desc.additional_constraints = 'one of: ' + ', '.join(map(str, md['choices']))
    if isinstance(f.default, tuple):
        first = f.default[0] if f.default else md.get('item_type', '')
        desc.type = {str: ParameterType.PARAMETER_STRING_ARRAY,
                     float: ParameterType.PARAMETER_DOUBLE_ARRAY,
                     int: ParameterType.PARAMETER_INTEGER_ARRAY}.get(
                         type(first) if f.default else first,
                         ParameterType.PARAMETER_STRING_ARRAY)
        desc.dynamic_typing = False
    return desc


def _ros_default(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def _get_value(node: Node, name: str) -> Any:
    """A declared parameter's value; an array left unset (YAML `[]`) reads as None."""
    try:
        return node.get_parameter(name).value
    except ParameterUninitializedException:
        return None


def _from_ros(f: dataclasses.Field, value: Any) -> Any:
    if isinstance(f.default, tuple):
        return tuple(value) if value is not None else ()
    if isinstance(f.default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def declare_config(node: Node, cls: type[T], prefix: str = '',
                   on_change: Callable[[T], None] | None = None) -> T:
    """Declare every field of settings dataclass `cls` as a ROS parameter and build it.

    Each parameter gets a descriptor with the field's description and range, so
    `ros2 param describe` explains it and rclpy rejects values out of range. Values
    that pass the descriptor but fail the dataclass's own checks are rejected too. The
    fields of a group (core.config.group) are parameters named ``<prefix><group>.<field>``
    (in YAML, a mapping under the group's name).

    Args:
        node: the node that owns the parameters.
        cls: a frozen dataclass validated in `__post_init__` (see core.config).
        prefix: parameter name prefix, e.g. 'gpod.' (empty for none).
        on_change: if given, parameters may change at run time; it receives the new
            validated settings. Without it, changes are refused.
    Returns:
        The settings built from the declared (YAML or command-line) values.
    Raises:
        ValueError: the start-up values are out of range (the message names the field),
            or a value is given under `prefix` for no setting (a misspelt or stale name
            would otherwise be dropped in silence and the default run instead).
    """
    fields = dict(flat_fields(cls, prefix))
    if prefix:
        unknown = sorted(n for n in _given_values(node)
                         if n.startswith(prefix) and n not in fields)
        if unknown:
            raise ValueError(f'no such setting: {", ".join(unknown)} (`asmonc params` or '
                             'docs/parameters.md lists them)')
    for name, f in fields.items():
        desc = _descriptor(f)
        default = _ros_default(f.default)
        if isinstance(default, list) and not default:
            # rclpy cannot type an empty list (it would become a BYTE_ARRAY): declare the
            # descriptor's array type with no value; unset reads back as empty.
            default = Parameter.Type(desc.type)
        node.declare_parameter(name, default, desc)
    values = {name[len(prefix):]: _from_ros(f, _get_value(node, name))
              for name, f in fields.items()}
    config = override(cls(), values)
    state = {'config': config}

    def _on_set(params) -> SetParametersResult:
        mine = [p for p in params if p.name in fields]
        if not mine:
            return SetParametersResult(successful=True)
        if on_change is None:
            return SetParametersResult(
                successful=False, reason='these settings are fixed at start-up')
        new = {p.name[len(prefix):]: _from_ros(fields[p.name], p.value) for p in mine}
        try:
            cfg = override(state['config'], new)
        except (ValueError, TypeError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        state['config'] = cfg
        on_change(cfg)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(_on_set)
    return config


class Diagnostics:
    """Publishes one DiagnosticStatus of a node on /diagnostics, at most `period` apart.

    Call `update(level, message, **values)` whenever the state changes; the status is
    republished periodically so a monitor sees the node is alive.
    """

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3

    def __init__(self, node: Node, name: str, hardware_id: str = '', period: float = 1.0):
        self._node = node
        self._pub = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._status = DiagnosticStatus(name=name, hardware_id=hardware_id,
                                        level=bytes([self.STALE]), message='starting')
        self._lock = threading.Lock()       # update and publish may run on two threads
        self._timer = node.create_timer(period, self.publish)

    @property
    def level(self) -> int:
        """Current level as an int (0 OK, 1 WARN, 2 ERROR, 3 STALE)."""
        return self._status.level[0]

    def update(self, level: int, message: str, publish: bool = False, **values: Any) -> None:
        """Set the status (level 0..3); publish at once if `publish` or it changed.

        `values` become the status's key/value pairs; they cannot be named `level`,
        `message` or `publish`.
        """
        level = level[0] if isinstance(level, bytes) else int(level)
        kv = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        with self._lock:
            changed = level != self.level or message != self._status.message
            self._status = DiagnosticStatus(name=self._status.name,
                                            hardware_id=self._status.hardware_id,
                                            level=bytes([level]), message=message, values=kv)
        if publish or changed:
            self.publish()

    def publish(self) -> None:
        msg = DiagnosticArray()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        with self._lock:
            msg.status = [self._status]     # replaced whole by `update`, never changed
        self._pub.publish(msg)


#: the log line of `watch_input_links` once an input has a publisher (read by `asmonc run`)
LINKED_LINE = 'input {topic}: {n} publisher(s) matched'


def watch_input_links(node: Node, topics: tuple[str, ...], period: float = 0.2) -> None:
    """Log once, per topic of `topics` the node subscribes, when its subscription has
    matched a publisher (`LINKED_LINE`), then stop watching.

    Seeing a node's subscription in the ROS graph does not mean the publisher's process
    has discovered it: DDS discovery between two processes can lag by seconds on a loaded
    machine (a lost announcement waits for the next one), and a message published before
    the match is lost. This line says the link itself is up; `asmonc run` waits for it
    before playing the bag, and a person starting nodes by hand sees it in the log.
    """
    pending = {s.topic_name: s for s in node.subscriptions if s.topic_name in topics}

    def _check() -> None:
        for topic, sub in list(pending.items()):
            n = sub.get_publisher_count()
            if n > 0:
                del pending[topic]
                node.get_logger().info(LINKED_LINE.format(topic=topic, n=n))
        if not pending:
            node.destroy_timer(timer)

    timer = node.create_timer(period, _check)


def config_overrides(config: Any) -> list[Parameter]:
    """Parameter overrides that make a node declare exactly the settings `config`
    (a settings dataclass), for building nodes in-process. An empty list becomes an
    unset override, which `declare_config` reads back as empty."""
    out = []
    for name, value in flat_values(config).items():
        if isinstance(value, tuple) and not value:
            out.append(Parameter(name, Parameter.Type.NOT_SET))
        else:
            out.append(Parameter(name, value=list(value) if isinstance(value, tuple) else value))
    return out


def quiet_interrupts() -> threading.Event:
    """Make Ctrl-C (SIGINT) shut ROS down cleanly instead of raising KeyboardInterrupt.

    Call before `rclpy.init`. Once rclpy is initialised its own handler shuts the
    contexts down (so spinning returns) and then calls this one, so Python does not raise
    KeyboardInterrupt at a random later point (e.g. while a bag is being finalised). A
    Ctrl-C before rclpy has installed its handler sets the returned event and shuts the
    default context down from a helper thread.

    Returns:
        An event set by the first SIGINT.
    """
    interrupted = threading.Event()
    if threading.current_thread() is threading.main_thread():
        def _on_sigint(signum, frame) -> None:
            interrupted.set()
            threading.Thread(target=_try_shutdown_default, daemon=True).start()

        signal.signal(signal.SIGINT, _on_sigint)
    return interrupted


def _try_shutdown_default() -> None:
    with contextlib.suppress(Exception):
        rclpy.try_shutdown()


def spin_until_shutdown(node: Node, interrupted: threading.Event | None = None,
                        period: float = 0.1) -> None:
    """Spin `node` until its context is shut down or `interrupted` is set.

    Unlike `rclpy.spin`, the executor wakes every `period` seconds, so a shutdown that did
    not wake the wait set (a Ctrl-C racing rclpy's signal handling) is still noticed and
    Python signal handlers get to run.
    """
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        while node.context.ok() and not (interrupted is not None and interrupted.is_set()):
            executor.spin_once(timeout_sec=period)
    finally:
        with contextlib.suppress(Exception):
            executor.remove_node(node)


def share_cpu_by_nice() -> bool:
    """Make this process's nice value count against the graph's other processes.

    Linux's autogroup scheduling (``kernel.sched_autogroup_enabled``) shares a CPU between
    sessions first and between the processes of a session second: a node started in a
    session of its own (``setsid``, as some launchers start children) gets a whole
    session's share whatever its nice value, and a niced node (the egomotion node, nice
    10) then takes as much of a single core as the detector. A process that leads its own
    session gives its autogroup its own nice value; one that shares its session changes
    nothing (the autogroup is the others' too). Returns True when it set the autogroup.
    """
    try:
        nice = os.getpriority(os.PRIO_PROCESS, 0)
        if nice <= 0 or os.getsid(0) != os.getpid():
            return False
        with open('/proc/self/autogroup', 'w') as f:
            f.write(str(nice))
        return True
    except OSError:             # no autogroups (not Linux, or turned off): nothing to do
        return False


def _given_values(node: Node) -> dict:
    """The values given for the node (params file, ``-p``) by name: rclpy keeps them
    in ``_parameter_overrides``, declared or not."""
    return getattr(node, '_parameter_overrides', {})


def undeclared_overrides(node: Node) -> list[str]:
    """The names given a value for the node (params file, ``-p``) that it has not
    declared, sorted: a misspelt or stale name, whose default runs instead."""
    return sorted(n for n in _given_values(node) if not node.has_parameter(n))


def warn_undeclared(node: Node) -> None:
    """Log one warning naming the values given for no parameter of the node. A warning,
    not an error: a params file's ``/**`` section gives its values to every node, also to
    those without such a setting (an error under a settings group's own prefix:
    `declare_config`)."""
    names = undeclared_overrides(node)
    if names:
        node.get_logger().warning(
            f'values given for no parameter of this node, ignored: {", ".join(names)} '
            '(`asmonc params` or docs/parameters.md lists the settings)')


def run_node(factory: Callable[..., Node], args: list[str] | None = None, *,
             name: str = 'asmonc_vision', errors: tuple[type[BaseException], ...] = (),
             failed: Callable[[Node], bool] | None = None, **kwargs: Any) -> None:
    """The Jazzy main: init, spin, exit cleanly on Ctrl-C or external shutdown.

    Settings out of range (ValueError/TypeError from the settings dataclass, or rclpy's
    parameter exceptions while the node is built) are logged as one clear error line and
    the process exits with status 2, as it does for the node's own fatal `errors`
    (logged by the node itself) or when `failed(node)` is true at the end.

    Args:
        factory: builds the node (called with `**kwargs`).
        args: command-line arguments for rclpy.
        name: logger name for errors raised before the node exists.
        errors: exception types that mean "cannot run" (exit status 2).
        failed: called with the node before it is destroyed; true means exit status 2.
    """
    interrupted = quiet_interrupts()
    share_cpu_by_nice()
    rclpy.init(args=args)
    node = None
    status = 0
    try:
        if not interrupted.is_set():
            node = factory(**kwargs)
            warn_undeclared(node)
            spin_until_shutdown(node, interrupted)
    except errors:
        status = 2
    except (ValueError, TypeError, InvalidParameterValueException,
            InvalidParameterTypeException) as exc:
        rclpy.logging.get_logger(name).error(f'invalid settings: {exc}')
        status = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:  # noqa: BLE001
        if rclpy.ok():
            raise
        # Ctrl-C while starting up: rcl calls fail once the context is shut down
    finally:
        if node is not None:
            if failed is not None and failed(node):
                status = 2
            node.destroy_node()
        rclpy.try_shutdown()
    if status:
        raise SystemExit(status)
