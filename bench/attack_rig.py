"""What the attack bench hears and how it speaks: the listener, the bench's rig and its
means to attack, the measures (lowest point, the loop's period as heard), and the attacks'
child processes (``python bench/attack_rig.py child flood|churn DOMAIN ...``).
"""

import math
from pathlib import Path
import subprocess
import sys
import time

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / 'test' / 'rigs'), str(HERE)]

from arm_rig import ArmRig, point, START_Q  # noqa: E402
from geometry_msgs.msg import PointStamped, TwistStamped  # noqa: E402
from goal_flood import flood_goals  # noqa: E402
import numpy as np  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
import rclpy  # noqa: E402
from rclpy.duration import Duration  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from ros_harness import ros_environment  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray, String  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.control.events import parse_event  # noqa: E402
from arm_control.nodes.common import COMMANDS, LATCHED  # noqa: E402

ARM, SIM = config.load('sim')
CONTROLLER = config.load('controller')[1]
PRESETS = {name: (x, y) for name, x, y in ARM.presets}
NOT_COMMANDING = ('no_sensors', 'estopped', 'disabled')
BIG = 10 * 1024 * 1024                  # the oversized text, 10 MB
READY_TIMEOUT_S = 90.0                  # bring-up, on a loaded machine too
LOAD_BUDGET_S = 1800.0                  # the busy loops stop by themselves after this
LISTENER_PRIORITY = 40                  # SCHED_FIFO of the threads that hear (below the nodes)

# What the listener keeps: every message of a burst, while this process is busy elsewhere.
DEEP = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
DEEP_LATCHED = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
# The events that answer a goal (failures later are not answers), and the one that counts
# a window's rejections beyond the burst ('goals_rejected: 1968 more goals rejected ...').
ANSWERS = ('goal_queued', 'goal_accepted', 'goal_rejected')
SUMMARY = 'goals_rejected'


def y_lowest_m(shoulder, elbow):
    """min(y_elbow, y_tool): y_elbow = La·sin θa, y_tool = y_elbow + Lb·sin(θa + θb)."""
    y_elbow = ARM.shoulder.length_m * np.sin(shoulder)
    return np.minimum(y_elbow, y_elbow + ARM.elbow.length_m * np.sin(shoulder + elbow))


def point_of(q):
    """The tool point (x, y) of a configuration."""
    shoulder, elbow = q
    upper, fore = ARM.shoulder.length_m, ARM.elbow.length_m
    return (upper * math.cos(shoulder) + fore * math.cos(shoulder + elbow),
            upper * math.sin(shoulder) + fore * math.sin(shoulder + elbow))


def short(text: str, keep: int = 160) -> str:
    return text if len(text) <= 2 * keep else \
        f'{text[:keep]}...[{len(text)} characters]...{text[-keep // 2:]}'


def arrival_s(info) -> float:
    """When DDS received the message (the system clock, s), else now."""
    stamp = info.get('received_timestamp') if isinstance(info, dict) else None
    return stamp * 1e-9 if stamp else time.time()


class Listener:
    """What the bench hears, each message with its DDS reception time (time.time() clock)."""

    def __init__(self, node):
        self.voltage_s = []             # arrival times of voltage_command
        self.truth = []                 # (t, shoulder, elbow), true angles
        self.states = []                # (t, arm_state)
        self.events = []                # (t, kind, goals it answers, text)
        self.arm2_state = ''
        self.clock = None               # the last /clock heard (simulated time)
        node.create_subscription(Clock, '/clock', self.on_clock, DEEP)
        node.create_subscription(Float64MultiArray, '/voltage_command', self.on_voltage, DEEP)
        node.create_subscription(JointState, '/sim/ground_truth', self.on_truth, DEEP)
        node.create_subscription(String, '/arm_state', self.on_state, DEEP_LATCHED)
        node.create_subscription(String, '/controller/events', self.on_event, DEEP)
        node.create_subscription(String, '/arm2/arm_state', self.on_arm2_state, LATCHED)

    def on_voltage(self, msg, info):
        self.voltage_s.append(arrival_s(info))

    def on_truth(self, msg, info):
        angles = dict(zip(msg.name, msg.position))
        if 'shoulder' in angles and 'elbow' in angles:
            self.truth.append((arrival_s(info), angles['shoulder'], angles['elbow']))

    def on_state(self, msg, info):
        self.states.append((arrival_s(info), msg.data))

    def on_event(self, msg, info):
        kind, _, sentence = parse_event(msg.data)
        answered = int(sentence.split()[0]) if kind == SUMMARY else int(kind in ANSWERS)
        self.events.append((arrival_s(info), kind, answered, short(msg.data)))

    def on_clock(self, msg):
        self.clock = msg.clock

    def on_arm2_state(self, msg):
        self.arm2_state = msg.data

    def answers(self, since_s: float, until_s: float = math.inf) -> int:
        return sum(count for t, _, count, _ in self.events if since_s <= t <= until_s)

    def said(self, since_s: float, *kinds) -> list:
        return [text for t, kind, _, text in self.events if t >= since_s and kind in kinds]

    def first_answer_s(self, since_s: float, kinds=('goal_accepted', 'goal_queued'),
                       about=''):
        for t, kind, _, text in self.events:
            if t >= since_s and kind in kinds and about in text:
                return t
        return None

    def truth_between(self, start_s: float, end_s: float) -> np.ndarray:
        rows = [row for row in self.truth if start_s <= row[0] <= end_s]
        return np.array(rows, float).reshape(-1, 3)


def period_ms(arrivals, start_s: float, end_s: float):
    """p50, p99 and worst gap (ms) between arrivals in [start_s, end_s], its edges counted:
    a controller silent at the end of the window shows."""
    inside = sorted(t for t in arrivals if start_s <= t <= end_s)
    gaps = 1000.0 * np.diff([start_s, *inside, end_s])
    return np.percentile(gaps, 50), np.percentile(gaps, 99), gaps.max(), len(inside)


def lowest_points_mm(heard: Listener, start_s: float, end_s: float):
    """(lowest while the controller commanded, lowest overall), mm, None without samples;
    and where the first was: (its time after start_s, the controller's state then)."""
    truth = heard.truth_between(start_s, end_s)
    if not len(truth):
        return None, None, None
    times, lowest = truth[:, 0], 1000.0 * y_lowest_m(truth[:, 1], truth[:, 2])
    state_times = np.array([t for t, _ in heard.states])
    states = [s for _, s in heard.states]
    voltage_times = np.sort(np.array(heard.voltage_s))
    where = np.searchsorted(state_times, times, side='right') - 1
    state = [states[i] if i >= 0 else '' for i in where]
    last = np.searchsorted(voltage_times, times, side='right') - 1
    fresh = (last >= 0) & (times - voltage_times[np.maximum(last, 0)]
                           <= SIM.command_timeout_s) if len(voltage_times) else \
        np.zeros(len(times), bool)
    commanding = fresh & np.array([s not in NOT_COMMANDING and s != '' for s in state])
    if not commanding.any():
        return None, lowest.min(), None
    index = np.flatnonzero(commanding)[np.argmin(lowest[commanding])]
    return lowest[index], lowest.min(), (times[index] - start_s, state[index])


class Bench:
    """The rig, what it hears, and the means to attack it."""

    def __init__(self, rig: ArmRig, heard: Listener, seconds: float):
        self.rig, self.heard, self.seconds = rig, heard, seconds
        node = rig.probe.node
        self.preset_pub = node.create_publisher(String, '/goal_preset', COMMANDS)
        self.set_state_pub = node.create_publisher(JointState, '/sim/set_state', COMMANDS)
        self.estop = node.create_client(Trigger, '/controller/estop')
        self.reset = node.create_client(Trigger, '/controller/reset')
        self.cancel = node.create_client(Trigger, '/controller/cancel')
        self.parameters = node.create_client(SetParameters, '/controller/set_parameters')
        self.children = []              # processes started by attacks, stopped at the end
        self.fresh_next = False         # the next attack needs the nodes started afresh

    # ------------------------------------------------------------------ waiting

    def wait_until(self, condition, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            if self.rig.spin_until(condition, min(0.5, max(left, 0.0))):
                return True
            self.trim()
            if time.monotonic() >= deadline:
                return condition()

    def wait(self, seconds: float) -> None:
        self.wait_until(lambda: False, seconds)

    def trim(self) -> None:
        """The rig keeps every message it hears (some of them 10 MB): keep the recent ones."""
        rig = self.rig
        for heard, keep in ((rig.truth, 5000), (rig.joint_states, 500), (rig.voltages, 500),
                            (rig.diagnostics, 20), (rig.events, 200), (rig.queue, 5),
                            (rig.states, 50)):
            del heard[:-keep]

    # ------------------------------------------------------------------ speaking

    def call(self, client, timeout_s: float = 5.0):
        """A Trigger call on a kept client; the response, or None without one in time."""
        if not self.wait_until(client.service_is_ready, timeout_s):
            return None
        future = client.call_async(Trigger.Request())
        if not self.wait_until(future.done, timeout_s):
            client.remove_pending_request(future)
            return None
        return future.result()

    def set_parameters(self, timeout_s: float = 5.0, **values) -> list:
        """``ros2 param set /controller`` each of ``values`` (dots as '__'), one by one: the
        (successful, reason) of each, or None where the call went unanswered."""
        client = self.parameters
        if not self.wait_until(client.service_is_ready, timeout_s):
            return [None] * len(values)
        results = []
        for name, value in values.items():
            request = SetParameters.Request(parameters=[
                Parameter(name.replace('__', '.'), value=value).to_parameter_msg()])
            future = client.call_async(request)
            if not self.wait_until(future.done, timeout_s):
                client.remove_pending_request(future)
                results.append(None)
                continue
            result = future.result().results[0]
            results.append((result.successful, result.reason))
        return results

    def publish(self, publisher, message, match_timeout_s: float = 5.0) -> None:
        self.wait_until(lambda: publisher.get_subscription_count() > 0, match_timeout_s)
        publisher.publish(message)

    def send(self, x, y, frame='arm_base') -> None:
        self.wait_until(lambda: self.rig.goal_pub.get_subscription_count() > 0, 5.0)
        self.rig.send(x, y, frame=frame)

    def child(self, *args) -> subprocess.Popen:
        """This script in another process (``child`` mode) on the rig's domain."""
        process = subprocess.Popen(
            [sys.executable, __file__, 'child', args[0], str(self.rig.domain),
             *map(str, args[1:])], env=ros_environment(self.rig.domain),
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.children.append(process)
        return process

    # ------------------------------------------------------------------ between attacks

    def prepare(self) -> None:
        """A held arm at its start: reset (sim reset, controller cleared), or started afresh
        when the last attack asked for it, a node died, or the reset did not take."""
        dead = [name for name, p in self.rig.processes.items() if not p.alive()]
        if self.fresh_next or dead:
            self.restart_all()
        else:
            try:
                self.settle()
            except (AssertionError, TimeoutError):
                self.restart_all()
        self.fresh_next = False

    def settle(self) -> None:
        if self.rig.state in ('estopped', 'error'):
            self.call(self.reset)
        self.call(self.cancel)
        self.rig.reset_sim()
        if not self.rig.wait_held(START_Q, timeout_s=1.5):
            # The controller took the sim's reset back to where it last held the arm: a
            # goal at the start puts every attack on the same footing.
            since = time.time()
            self.send(*point_of(START_Q))
            if not self.wait_until(lambda: self.heard.said(since, 'goal_reached'), 10.0):
                raise TimeoutError('the arm did not go back to its start')

    def restart_all(self) -> None:
        self.rig.close()
        del self.rig.states[:], self.rig.diagnostics[:]
        self.rig.start_all()
        self.rig.ready(READY_TIMEOUT_S)

    def close(self) -> None:
        for process in self.children:
            if process.poll() is None:
                process.kill()
            process.wait()


# ---------------------------------------------------------------------- child processes


def flood_child(domain: int, count: int) -> None:
    """Publish ``count`` goals at once, good and bad in turn, from a publisher that keeps
    them all until the controller has them (or 30 s pass)."""
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('attack_flood', context=context)
    publisher = node.create_publisher(
        PointStamped, '/goal_point',
        QoSProfile(depth=count, reliability=ReliabilityPolicy.RELIABLE))
    deadline = time.monotonic() + 10.0
    while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    goals = [point(**goal) for goal in flood_goals()]
    began = time.monotonic()
    for index in range(count):
        publisher.publish(goals[index % len(goals)])
    published_s = time.monotonic() - began
    acked = publisher.wait_for_all_acked(Duration(seconds=30.0))
    print(f'{count} published in {published_s:.2f} s, all acknowledged: {acked}')
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def flood_all_child(domain: int, rate_hz: float, seconds: float) -> None:
    """goal_point, goal_preset and driver_velocity, each at ``rate_hz`` for ``seconds``,
    from publishers as a user's (reliable, depth 10), good and bad goals in turn."""
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('attack_flood_all', context=context)
    goals = node.create_publisher(PointStamped, '/goal_point', COMMANDS)
    presets = node.create_publisher(String, '/goal_preset', COMMANDS)
    driver = node.create_publisher(TwistStamped, '/driver_velocity', COMMANDS)
    deadline = time.monotonic() + 10.0
    while min(p.get_subscription_count() for p in (goals, presets, driver)) == 0 and \
            time.monotonic() < deadline:
        time.sleep(0.05)
    points = [point(**goal) for goal in flood_goals()]
    names = list(PRESETS) + ['no_such_preset']
    twist = TwistStamped()
    twist.header.frame_id = 'arm_base'
    began, sent = time.monotonic(), 0
    while time.monotonic() - began < seconds:
        goals.publish(points[sent % len(points)])
        presets.publish(String(data=names[sent % len(names)]))
        twist.twist.linear.x = 0.2 * math.sin(sent / 50.0)
        driver.publish(twist)
        sent += 1
        time.sleep(max(0.0, began + sent / rate_hz - time.monotonic()))
    print(f'{sent} of each published in {time.monotonic() - began:.1f} s')
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def churn_child(domain: int, count: int, lifetime_s: float, interval_s: float) -> None:
    """``count`` nodes, one every ``interval_s``, each living ``lifetime_s`` with a
    participant of its own, a publisher, two subscriptions to the arm's topics and a
    service, as a user's tools come and go."""
    live, started, next_s = [], 0, time.monotonic()
    began = time.monotonic()
    while started < count or live:
        now = time.monotonic()
        if started < count and now >= next_s:
            context = rclpy.Context()
            rclpy.init(context=context, domain_id=domain)
            node = rclpy.create_node(f'churn_{started}', context=context)
            chatter = node.create_publisher(String, '/churn/chatter', 10)
            node.create_subscription(JointState, '/joint_states', lambda m: None, 10)
            node.create_subscription(Float64MultiArray, '/voltage_command', lambda m: None, 10)
            node.create_service(Trigger, f'/churn_{started}/ping', lambda q, r: r)
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)
            live.append((now, context, node, chatter, executor))
            started += 1
            next_s += interval_s
        for entry in [e for e in live if now - e[0] >= lifetime_s]:
            _, context, node, _, executor = entry
            executor.shutdown()
            node.destroy_node()
            rclpy.try_shutdown(context=context)
            live.remove(entry)
        for _, _, _, chatter, executor in live:
            chatter.publish(String(data='churn'))
            executor.spin_once(timeout_sec=0.0)
        time.sleep(0.02)
    print(f'{count} nodes came and went in {time.monotonic() - began:.1f} s')


if __name__ == '__main__':
    if sys.argv[1:2] == ['child']:
        kind, numbers = sys.argv[2], [float(v) for v in sys.argv[3:]]
        if kind == 'flood':
            flood_child(int(numbers[0]), int(numbers[1]))
        elif kind == 'flood_all':
            flood_all_child(int(numbers[0]), numbers[1], numbers[2])
        else:
            churn_child(int(numbers[0]), int(numbers[1]), numbers[2], numbers[3])
