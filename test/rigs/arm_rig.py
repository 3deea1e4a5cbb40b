"""sim, planner and controller as processes for a whole test module, seen by one probe.

``ArmRig`` starts the installed executables on one ROS domain, restarts, pauses (SIGSTOP)
and resumes them, reads their memory from /proc, and keeps what the probe hears with the
time it arrived (``time.monotonic()``): ground truth, joint states, voltage commands, the
arm's state, the controller's events, queue and diagnostics.

Run as a script, ``python arm_rig.py flood DOMAIN RATE_HZ SECONDS`` publishes goals of every
kind (good, NaN, inf, huge, wrong frame, z off the plane, out of reach, forbidden) at
RATE_HZ for SECONDS from a process of its own, and prints how many it sent.
"""

import math
import os
from pathlib import Path
import signal
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path as PathMsg
from nav_msgs.srv import GetPlan
import numpy as np
from ros_harness import lasting, stamp_s
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger

from arm_control import config
from arm_control.control.events import parse_event
from arm_control.model.world import ForbiddenSpace
from arm_control.nodes.common import COMMANDS, controller_sees_planner, LATCHED

START_Q = np.array(config.load('sim')[1].initial_position)
FORBIDDEN = ForbiddenSpace(config.load('controller')[0])
DEG = math.pi / 180.0
# Bad goals of every kind, each with the cause its rejection must give.
BAD_GOALS = [
    (dict(x=math.nan, y=1.0), 'not finite'),
    (dict(x=1.0, y=math.inf), 'not finite'),
    (dict(x=-math.inf, y=1.0, z=math.nan), 'not finite'),
    (dict(x=1e300, y=-1e300), 'out of reach'),
    (dict(x=1.0, y=1.0, frame='map'), 'wrong frame'),
    (dict(x=1.0, y=1.0, z=0.05), 'off the plane'),
    (dict(x=3.0, y=0.0), 'out of reach'),
    (dict(x=1.0, y=-0.5), 'forbidden'),
    (dict(x=1.8, y=0.0), 'forbidden'),
]


def point(x, y, z=0.0, frame='arm_base') -> PointStamped:
    message = PointStamped()
    message.header.frame_id = frame
    message.point.x, message.point.y, message.point.z = float(x), float(y), float(z)
    return message


class Heard(list):
    """(arrival time, message) pairs, in order."""

    def messages(self, since_s=-math.inf):
        return [m for t, m in self if t >= since_s]

    def last(self):
        return self[-1][1] if self else None

    def lasting(self, since_s: float, span_s: float) -> list:
        """``ros_harness.lasting`` of the messages heard since ``since_s``, looking back from
        the last only as far as it needs."""
        recent = []
        for arrived, message in reversed(self):
            if arrived < since_s:
                break
            recent.append(message)
            if stamp_s(message) <= stamp_s(self[-1][1]) - span_s:
                break
        return lasting(recent[::-1], span_s)


def assert_never_forbidden(rig, since_s: float) -> None:
    """The sim's true state, since ``since_s``, never in forbidden space; else say when, how
    deep and for how long, with what the controller said meanwhile."""
    heard = [(t, m) for t, m in rig.truth if t >= since_s]
    q = np.array([m.position for _, m in heard]).reshape(-1, 2)
    free = np.asarray(FORBIDDEN.is_free(q))
    if np.all(free):
        return
    times = np.array([t for t, _ in heard])[~free] - since_s
    depth_mm = -1000 * np.min(FORBIDDEN.lowest_point_m(q[~free]))
    raise AssertionError(
        f'{np.sum(~free)} true samples in forbidden space, {depth_mm:.0f} mm deep, from '
        f'{times[0]:.2f} s to {times[-1]:.2f} s; first: {FORBIDDEN.why_forbidden(q[~free][0])} '
        f'at {np.round(np.degrees(q[~free][0]), 1)} deg\n{rig.event_log(since_s)}')


def diagnostic_values(message: DiagnosticArray, name: str) -> dict:
    for item in message.status:
        if item.name == name:
            return {'level': int.from_bytes(item.level, 'little')
                    if isinstance(item.level, bytes) else int(item.level),
                    'message': item.message, **{kv.key: kv.value for kv in item.values}}
    return {}


def rss_mb(pid: int) -> float:
    """Resident memory of a process (VmRSS in /proc/<pid>/status), MB; NaN once it is gone."""
    try:
        status = Path(f'/proc/{pid}/status').read_text()
    except OSError:
        return math.nan
    for line in status.splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024.0
    return math.nan


def cpu_s(pid: int) -> float:
    """CPU time a process has used, all its threads, user and system (/proc/<pid>/stat), s."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def thread_cpu_s(pid: int) -> dict:
    """CPU time each thread of a process has used, by thread id (/proc/<pid>/task), s."""
    used = {}
    for task in Path(f'/proc/{pid}/task').iterdir():
        try:
            fields = (task / 'stat').read_text().rsplit(')', 1)[1].split()
        except OSError:                     # the thread ended meanwhile
            continue
        used[int(task.name)] = (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
    return used


def periods(times) -> np.ndarray:
    return np.diff(np.asarray(times, float))


class ArmRig:
    """The three nodes on ``domain``; ``probe`` (ros_harness.Probe) listens and speaks."""

    NODES = ('sim', 'planner', 'controller')

    def __init__(self, domain: int, probe, log_dir: Path, node_args=None):
        from ros_harness import NodeProcess
        self._node_process = NodeProcess
        self.domain = domain
        self.probe = probe
        self.log_dir = Path(log_dir)
        self.node_args = dict(node_args or {})
        self.processes = {}
        self.retired = []
        node = probe.node
        self.truth = self._hear(JointState, '/sim/ground_truth', 10)
        self.joint_states = self._hear(JointState, '/joint_states', 10)
        self.voltages = self._hear(Float64MultiArray, '/voltage_command', COMMANDS)
        self.states = self._hear(String, '/arm_state', LATCHED)
        self.events = self._hear(String, '/controller/events', 1000)
        self.queue = self._hear(PathMsg, '/controller/goal_queue', LATCHED)
        self.diagnostics = self._hear(DiagnosticArray, '/diagnostics', 50)
        self.goal_pub = node.create_publisher(PointStamped, '/goal_point', COMMANDS)
        self.plan_client = node.create_client(GetPlan, '/plan_path')

    def _hear(self, msg_type, topic, qos) -> Heard:
        heard = Heard()
        self.probe.node.create_subscription(
            msg_type, topic, lambda m: heard.append((time.monotonic(), m)), qos)
        return heard

    # ------------------------------------------------------------------ processes

    def start(self, name: str, *ros_args):
        """Start (or start again) the node ``name``; the old process is kept for its log."""
        old = self.processes.get(name)
        if old is not None:
            self.retired.append(old)
        args = tuple(self.node_args.get(name, ())) + ros_args
        log_dir = self.log_dir / f'{name}_{len(self.retired)}'
        log_dir.mkdir(parents=True, exist_ok=True)
        self.processes[name] = self._node_process(name, self.domain, args, log_dir)
        return self.processes[name]

    def start_all(self) -> None:
        for name in self.NODES:
            self.start(name)

    def signal(self, name: str, signum) -> None:
        os.kill(self.processes[name].process.pid, signum)

    def pause(self, name: str) -> None:
        self.signal(name, signal.SIGSTOP)

    def resume(self, name: str) -> None:
        self.signal(name, signal.SIGCONT)

    def kill(self, name: str) -> None:
        """SIGKILL: a crash, no goodbye (no 0 V on the way out)."""
        process = self.processes[name]
        self.signal(name, signal.SIGCONT)
        self.signal(name, signal.SIGKILL)
        process.process.wait(10)

    def rss_mb(self, name: str) -> float:
        return rss_mb(self.processes[name].process.pid)

    def cpu_s(self, name: str) -> float:
        return cpu_s(self.processes[name].process.pid)

    def thread_cpu_s(self, name: str) -> dict:
        return thread_cpu_s(self.processes[name].process.pid)

    def output(self, name: str) -> str:
        return self.processes[name].output()

    def close(self) -> None:
        for process in list(self.processes.values()):
            try:
                os.kill(process.process.pid, signal.SIGCONT)
            except ProcessLookupError:
                pass
            process.stop()

    # ------------------------------------------------------------------ waiting

    def spin_until(self, condition, timeout_s: float) -> bool:
        return self.probe.spin_until(condition, timeout_s)

    def spin_for(self, duration_s: float) -> None:
        self.probe.spin_for(duration_s)

    @property
    def state(self) -> str:
        message = self.states.last()
        return message.data if message is not None else ''

    def wait_state(self, state: str, timeout_s: float = 10.0, since_s=-math.inf) -> bool:
        return self.spin_until(lambda: self.state == state and self.states[-1][0] >= since_s
                               if since_s > -math.inf else self.state == state, timeout_s)

    def said(self, kind: str, since_s=-math.inf) -> list:
        """The events of ``kind`` since ``since_s``, as (kind, cause, sentence)."""
        parsed = [parse_event(m.data) for m in self.events.messages(since_s)]
        return [event for event in parsed if event[0] == kind]

    def wait_said(self, kind: str, timeout_s: float = 10.0, since_s=-math.inf,
                  count: int = 1) -> bool:
        return self.spin_until(lambda: len(self.said(kind, since_s)) >= count, timeout_s)

    def reach_in_tries(self, x, y, tries: int = 3, timeout_s: float = 20.0) -> bool:
        """Send the goal until it is reached, at most ``tries`` times; each try must end
        reached or failed with its reason (never silent) within ``timeout_s``."""
        for _ in range(tries):
            tried = time.monotonic()
            self.send(x, y)
            assert self.spin_until(lambda: self.said('goal_reached', tried)
                                   or self.said('goal_failed', tried), timeout_s), \
                self.event_log(tried)
            if self.said('goal_reached', tried):
                return True
        return False

    def said_at(self, kind: str, since_s=-math.inf) -> float:
        """When the first event of ``kind`` since ``since_s`` was heard."""
        return min(t for t, m in self.events if t >= since_s and parse_event(m.data)[0] == kind)

    def events_heard(self, since_s=-math.inf) -> list:
        """The events heard since ``since_s``, as published."""
        return [m.data for m in self.events.messages(since_s)]

    def event_log(self, since_s=-math.inf) -> str:
        """The same, one a line: an assertion's message in full (pytest shortens a list)."""
        return '\n'.join(['events heard:'] + self.events_heard(since_s))

    def ready(self, timeout_s: float = 40.0) -> None:
        """Wait for the planner and the controller, then put the arm at its start, held."""
        assert self.spin_until(lambda: self.controller_sees_planner()
                               and self.state == 'waiting'
                               and self.goal_pub.get_subscription_count() > 0, timeout_s), \
            f'not ready: arm_state {self.state!r}, planner {self.controller_sees_planner()}'
        self.reset_sim()

    def reset_sim(self) -> None:
        """The arm back at its start, then held still by the controller: there, or -- if it
        sagged while the controller was starting (joint states late on a busy machine: 0 V)
        and the reset's jump is one the PID takes back -- where the controller last held it."""
        assert self.call(Trigger, '/sim/reset').success

        def holding():
            voltage = self.voltages.last()
            return self.state == 'waiting' and voltage is not None and \
                max(abs(v) for v in voltage.data) > 0.3        # against gravity
        assert self.wait_held(START_Q, timeout_s=3.0) or (self.wait_still() and holding()), (
            f'the controller did not take over the arm: arm_state {self.state!r}, true '
            f'position {self.truth.last().position if self.truth else None}, events '
            f'{self.event_log()}, processes alive '
            f'{ {n: p.alive() for n, p in self.processes.items()} }')

    def wait_held(self, q, tolerance_rad=2.0 * DEG, hold_s=0.5, timeout_s=10.0) -> bool:
        """Wait for the true state to stay within tolerance of ``q`` for ``hold_s``."""
        q = np.asarray(q, float)
        since = time.monotonic()

        def held():
            recent = self.truth.lasting(since, hold_s)
            return bool(recent) and all(
                np.max(np.abs(np.array(m.position) - q)) < tolerance_rad for m in recent)
        return self.spin_until(held, timeout_s)

    def wait_still(self, hold_s=0.5, speed_rad_s=0.05, timeout_s=10.0) -> bool:
        since = time.monotonic()

        def still():
            recent = self.truth.lasting(since, hold_s)
            return bool(recent) and all(
                np.max(np.abs(np.array(m.velocity))) < speed_rad_s for m in recent)
        return self.spin_until(still, timeout_s)

    def true_q(self) -> np.ndarray:
        return np.array(self.truth.last().position)

    def call(self, srv_type, name: str, request=None, timeout_s: float = 10.0,
             idempotent: bool = False):
        return self.probe.call(srv_type, name, request or srv_type.Request(), timeout_s,
                               idempotent)

    def send(self, x, y, z=0.0, frame='arm_base') -> None:
        self.goal_pub.publish(point(x, y, z, frame))

    def controller_diagnostics(self, since_s=-math.inf) -> list:
        """The controller's diagnostic values (a dict per message) since ``since_s``."""
        out = []
        for message in self.diagnostics.messages(since_s):
            values = diagnostic_values(message, '/controller')
            if values:
                out.append(values)
        return out

    def controller_sees_planner(self) -> bool:
        """The controller's own client reaches the planner, by its latest diagnostics."""
        for message in reversed(self.diagnostics.messages(-math.inf)):
            seen = controller_sees_planner(message)
            if seen is not None:
                return seen
        return False

    def node_diagnostics(self, name: str, since_s=-math.inf) -> list:
        out = []
        for message in self.diagnostics.messages(since_s):
            values = diagnostic_values(message, name)
            if values:
                out.append(values)
        return out
