"""What every node shell shares: parameters from the one file, QoS by use, and main()."""

import difflib
import functools
import gc
import math
import os
from pathlib import Path
import signal
import statistics
import sys
from typing import Optional

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
import rclpy
from rclpy.callback_groups import CallbackGroup
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
import yaml

from arm_control.parameters import (default_parameter_file, package_parameter_names,
                                    parameter_descriptions, ParameterError,
                                    read_parameter_file)

# QoS named for its use.
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)   # maps, plans, states
COMMANDS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
STATE_STREAM = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)

# Fast DDS's shared-memory transport ties the processes together: the first send to a new
# peer's port checks the port's health, and a failed check sleeps 333 ms holding a lock every
# send of the process waits on, while rclpy keeps Python's lock (config/fastdds_localhost_udp.xml).
# So the nodes talk over UDP. Jazzy's LOCALHOST discovery adds shared memory of its own and
# ignores FASTDDS_BUILTIN_TRANSPORTS; there the same discovery comes from an XML profile.
LOCALHOST_UDP_PROFILE = 'fastdds_localhost_udp.xml'


def localhost_udp_environment() -> dict:
    """The variables that give LOCALHOST discovery over UDP only (Fast DDS 2.x's name for
    the profile file; the profile names its peers, so the RMW must not add its own)."""
    return {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SYSTEM_DEFAULT',
            'FASTRTPS_DEFAULT_PROFILES_FILE': str(default_parameter_file(LOCALHOST_UDP_PROFILE))}


def use_udp_transport(environ=os.environ) -> None:
    """Before rclpy.init: Fast DDS over UDP, with the discovery range asked for. A profile,
    a transport or static peers the user set are kept."""
    chosen = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_BUILTIN_TRANSPORTS', 'ROS_STATIC_PEERS')
    if environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE') == 'LOCALHOST' and \
            not any(environ.get(name) for name in chosen):
        environ.update(localhost_udp_environment())
    else:
        environ.setdefault('FASTDDS_BUILTIN_TRANSPORTS', 'UDPv4')


# The controller's diagnostics key saying whether its client reaches the planner.
PLANNER_AVAILABLE = 'planner available'

# Parameters that name further parameters: (list parameter, prefix of the named ones).
_NAMED_BY_LIST = (('world.forbidden_regions', 'world.regions.'), ('presets.names', 'presets.'))


def declare_parameters(node, node_name: str, tunable=(), on_change=None) -> dict:
    """Declare every parameter of ``node_name`` with its default and description from
    the installed ``config/arm.yaml``; return ``{name: value}`` after any overrides.

    Types are checked by ``arm_control.config``, which names the parameter on failure,
    so the descriptors allow any type (a 30 for a 30.0 is not an error). Parameters named
    in ``tunable`` (a name, or a prefix ending in '.') may change at run time: each change
    is offered to ``on_change(parameters)`` -- every parameter, the new values in -- which
    returns None to take it or the reason to refuse it; the rest are read-only.
    """
    path = default_parameter_file()
    defaults = read_parameter_file(path, node_name)
    descriptions = parameter_descriptions(path, node_name)
    declared = []

    def declare(name, value):
        live = any(name == t or (t.endswith('.') and name.startswith(t)) for t in tunable)
        node.declare_parameter(name, value, ParameterDescriptor(
            description=descriptions.get(name, ''), dynamic_typing=True, read_only=not live))
        declared.append(name)

    for name, value in defaults.items():
        declare(name, value)
    for list_name, prefix in _NAMED_BY_LIST:
        if node.has_parameter(list_name):
            for item in node.get_parameter(list_name).value or ():
                if isinstance(item, str) and not node.has_parameter(prefix + item):
                    declare(prefix + item, None)
    _refuse_unknown(node, package_parameter_names(path))

    def offered(changes) -> SetParametersResult:
        """Refused unless every name is the package's and live, and ``on_change`` takes the
        whole. ROS's own (``use_sim_time``) are read at start: switched at run time, the
        controller's loop waited for a /clock that never came and the arm fell."""
        fixed = [change.name for change in changes if change.name not in declared]
        if on_change is None or fixed:
            return SetParametersResult(successful=False, reason=(
                f"parameter {', '.join(map(repr, fixed))} is " if fixed else 'parameters are ')
                + 'read once at start; restart the node to change it')
        values = {name: node.get_parameter(name).value for name in declared}
        values.update({change.name: change.value for change in changes})
        try:
            reason = on_change(values)
        except Exception as error:      # a change is refused, never the node's end
            reason = f'refused: {error!r}'
        return SetParametersResult(successful=reason is None, reason=reason or '')
    node.add_on_set_parameters_callback(offered)
    return {name: node.get_parameter(name).value for name in declared}


def _refuse_unknown(node, known) -> None:
    """A name given to the node that no node of the package reads is a typo or an old name:
    said at start, rather than silently doing nothing. (Names for other nodes in a ``/**``
    section are fine; so are ROS's own, such as ``qos_overrides.``.)"""
    listed = tuple(prefix for _, prefix in _NAMED_BY_LIST)
    for name in node._parameter_overrides:      # rclpy keeps the overrides given to the node
        if node.has_parameter(name) or name in known or name.startswith(listed) \
                or name.startswith('qos_overrides.'):
            continue
        close = difflib.get_close_matches(name, sorted(known), n=1, cutoff=0.6) or [
            k for k in sorted(known) if k.endswith('.' + name)]
        hint = f" (did you mean '{close[0]}'?)" if close else ''
        raise ParameterError(f"parameter '{name}' is not a parameter of arm_control{hint}")


def controller_sees_planner(message: DiagnosticArray,
                            controller: Optional[str] = None) -> Optional[bool]:
    """Whether the controller's own client reaches the planner, from its diagnostics (None
    if the message is not the controller's; ``controller``: its full name, when several
    arms share /diagnostics). Another node's view is no substitute: it may discover the
    planner before the controller does, and a goal sent then fails."""
    for status_ in message.status:
        if controller is not None and status_.name != controller:
            continue
        for value in status_.values:
            if value.key == PLANNER_AVAILABLE:
                return value.value == 'True'
    return None


class NodePart:
    """A part of a node (its ``node``) whose ``guarded`` callbacks count a failure and log it
    on the node."""

    @property
    def bad_inputs(self) -> int:        # ``guarded`` counts a failed callback on the node
        return self.node.bad_inputs

    @bad_inputs.setter
    def bad_inputs(self, count: int) -> None:
        self.node.bad_inputs = count

    def get_logger(self):
        return self.node.get_logger()


def guarded(callback):
    """A callback that logs what it raises instead of stopping the node: no message, however
    malformed, may take a node down (a service still answers, unsuccessfully)."""
    @functools.wraps(callback)
    def wrapper(self, *args):
        try:
            return callback(self, *args)
        except Exception as error:
            self.bad_inputs += 1
            self.get_logger().error(f'{callback.__name__} failed on its input: {error!r}',
                                    throttle_duration_sec=1.0)
            response = next((a for a in args if hasattr(a, 'success')), None)
            if response is not None:               # a service's: answered, unsuccessfully
                response.success, response.message = False, f'failed: {error!r}'
            return response
    return wrapper


def output(node, kind, topic: str, qos):
    """A publisher with no QoS event handlers: each handler is one more entity the executor
    gathers on every wake, hundreds a second in the controller; a subscriber whose QoS does
    not match says so itself."""
    return node.create_publisher(kind, topic, qos,
                                 event_callbacks=PublisherEventCallbacks(
                                     use_default_callbacks=False))


def listen(node, kind, topic: str, handler, qos, callback_group=None):
    """A subscription with no QoS event handlers, as ``output``'s publishers: a publisher
    whose QoS or type does not match says so itself (rclpy's and rclcpp's do by default)."""
    return node.create_subscription(kind, topic, handler, qos, callback_group=callback_group,
                                    event_callbacks=SubscriptionEventCallbacks(
                                        use_default_callbacks=False))


class Drained(CallbackGroup):
    """Subscriptions no executor waits on or calls back: their messages stay in their readers
    until the node takes them (``take_all``), in one thread of its choice. For inputs read at
    a beat of the node's own (the controller's readings, at its loop's tick): each message
    would wake the executor, which gathers every entity of the node on every wake."""

    def can_execute(self, entity) -> bool:
        return False

    def beginning_execution(self, entity) -> bool:
        return False

    def ending_execution(self, entity) -> None:
        pass


def take_all(subscription, handler, received=False) -> None:
    """Every message waiting in ``subscription``'s reader, oldest first, to ``handler``;
    ``received``: with the instant it reached this process too (ns of the system clock, 0
    where the middleware does not say)."""
    while True:
        with subscription.handle:
            taken = subscription.handle.take_message(subscription.msg_type, subscription.raw)
        if taken is None:
            return
        if received:
            handler(taken[0], int(taken[1].get('received_timestamp') or 0))
        else:
            handler(taken[0])


def log_at(logger, level: str, text: str) -> None:
    """``text`` at 'info', 'warning' or else error severity (rclpy ties a severity to its
    call site, so each has its own)."""
    if level == 'info':
        logger.info(text)
    elif level == 'warning':
        logger.warning(text)
    else:
        logger.error(text)


def loop_statistics(periods_s, compute_s) -> dict:
    """Mean and worst of a loop's periods, median and worst of its compute times (s)."""
    return {'mean': statistics.fmean(periods_s) if periods_s else math.nan,
            'worst': max(periods_s, default=math.nan),
            'compute median': statistics.median(compute_s) if compute_s else math.nan,
            'compute worst': max(compute_s, default=math.nan)}


def status(node, level, message: str, values: dict) -> DiagnosticStatus:
    """A DiagnosticStatus named after the node, with ``values`` as key/value pairs."""
    return DiagnosticStatus(
        level=level, name=node.get_fully_qualified_name(), message=message,
        hardware_id='arm_control',
        values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])


def _parameters_without_value(argv) -> list:
    """The parameters given no value in the --params-file files of ``argv`` ('name' quoted):
    rcl refuses such a file but names only the line."""
    def empty(tree, prefix):
        for key, value in tree.items():
            if isinstance(value, dict):
                yield from empty(value, f'{prefix}{key}.')
            elif value is None:
                yield f"'{prefix}{key}'"
    names = []
    for flag, path in zip(argv, argv[1:]):
        try:
            document = yaml.safe_load(Path(path).read_text(encoding='utf-8')) \
                if flag == '--params-file' else None
        except (OSError, yaml.YAMLError):
            continue
        for section in document.values() if isinstance(document, dict) else ():
            if isinstance(section, dict) and isinstance(section.get('ros__parameters'), dict):
                names += empty(section['ros__parameters'], '')
    return names


_stopping = False                  # a SIGINT or SIGTERM came (``interrupt``)


def _stop_once() -> None:
    """The stop is remembered, and later SIGINTs and SIGTERMs are ignored: a Ctrl-C under
    ``ros2 launch`` comes twice (the terminal's to the process group, and launch's), and
    the second one, landing in the clean-up or the interpreter's exit, would end the node
    with a traceback or exit code -2 (launch still kills a node that does not end)."""
    global _stopping
    _stopping = True
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, signal.SIG_IGN)


def interrupt(signum, frame):
    """SIGINT and SIGTERM as Ctrl-C, for a node that cleans up itself (``on_shutdown``)."""
    _stop_once()
    raise KeyboardInterrupt


def _note_stop(signum, frame):
    """SIGINT, after rclpy's own handler has begun the shutdown: only remembered. Raising
    here too would land wherever the main thread is by then, clean-up included."""
    _stop_once()


def start_ros(args, name: str) -> int:
    """rclpy.init over UDP (``use_udp_transport``): 0, or 2 with the reason logged."""
    use_udp_transport()
    # Python's handler for SIGINT, marking the stop: rclpy's, installed by init, runs first
    # and then this one. A Ctrl-C that lands while rclpy converts a message taken surfaces
    # as "Unable to convert call argument" before rclpy has shut the context down; marked,
    # it is taken as the stop it is, not as an error.
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _note_stop)
    try:
        rclpy.init(args=args)
    except Exception as error:      # a parameter file rcl cannot parse, a bad --ros-args
        empty = _parameters_without_value(sys.argv if args is None else args)
        named = f"; parameter {', '.join(empty)} has no value" if empty else ''
        rclpy.logging.get_logger(name).fatal(f'cannot start: {error}{named}')
        return 2
    return 0


def join_early(args, name: str):
    """``start_ros``, then a hidden node that makes the process's DDS participant now (rclpy
    makes it with the first node), so that it is discovered while the process still loads:
    found later, it found the nodes already there only at their next announcement. Returns
    the node (keep it), or the exit code. The node takes none of the command line's remaps
    (``-r __node:=controller`` would make it a second controller)."""
    failed = start_ros(args, name)
    if failed:
        return failed
    return rclpy.create_node(f'_{name}_joining', start_parameter_services=False,
                             enable_rosout=False, use_global_arguments=False)


def run(node_class, args=None, executor_class=None) -> int:
    """The Jazzy main() shape: construct, spin (on the global executor, or a new
    ``executor_class``), clean up on every exit path.

    A bad parameter stops the node at start with the parameter named (exit code 2). A node
    that ends by itself may say how it went in ``exit_code``.
    """
    if not rclpy.ok():                          # (``join_early`` may have)
        failed = start_ros(args, node_class.__name__)
        if failed:
            return failed
    node = None
    try:
        node = node_class()
        # What start-up made lives as long as the node: keep it out of the collector's full
        # passes, which otherwise stop every thread for ~0.1 s now and then.
        gc.freeze()
        rclpy.spin(node, None if executor_class is None else executor_class())
    except (ParameterError, ParameterException) as error:
        rclpy.logging.get_logger(node_class.__name__).fatal(f'bad parameter: {error}')
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok() and not _stopping:
            raise
        # Ctrl-C shut the context down beneath a callback still running, or came in the
        # middle of taking a message (rclpy then says it could not convert it): shutdown.
    finally:
        if node is not None:
            shutdown = getattr(node, 'on_shutdown', None)
            if shutdown is not None:
                shutdown()
            node.destroy_node()
        rclpy.try_shutdown()
    return getattr(node, 'exit_code', 0)
