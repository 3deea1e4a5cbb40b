"""``arm``: send the controller a goal, a preset or an e-stop, or read its state, and exit.

    arm goal 1.1 0.9            # a point (m) in arm_base: queued, accepted or rejected, and why
    arm preset high_score       # a preset of presets.names: replaces the queue, like a button
    arm estop | reset | cancel  # the controller's Trigger services, with their answer
    arm state                   # the state machine's state and the joint angles

A goal waits (and says so once) until the controller hears it and will tell its answer; then
it is sent and the controller's answer on ``controller/events`` is printed (a goal sent
before the controller has found its planner is queued until it has). ``--reach`` waits on
for ``goal_reached``. Every wait is bounded by ``--timeout``. Exit code: 0 done, 1 refused
(the reason printed), 3 no answer in time. The same tool is ``ros2 run arm_control arm ...``
and, without the ros2 CLI, ``scripts/arm ...`` from the two-command set-up. Names are
relative: ``--ros-args -r __ns:=/arm1`` talks to the arm in /arm1.
"""

import argparse
import math
import sys
import time

from geometry_msgs.msg import PointStamped
import rclpy
from rclpy.node import Node
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from arm_control.config import FRAME_ID
from arm_control.control.events import EventKind, parse_event
from arm_control.nodes.common import COMMANDS, LATCHED, STATE_STREAM, use_udp_transport

DONE, REFUSED, NO_ANSWER = 0, 1, 3
ANSWERS = {str(EventKind.GOAL_QUEUED): DONE, str(EventKind.GOAL_ACCEPTED): DONE,
           str(EventKind.GOAL_REJECTED): REFUSED, str(EventKind.GOALS_REJECTED): REFUSED}
ENDS = {str(EventKind.GOAL_REACHED): DONE, str(EventKind.GOAL_FAILED): REFUSED,
        str(EventKind.CANCELLED): REFUSED, str(EventKind.ESTOP): REFUSED,
        str(EventKind.CONTROL_FAILED): REFUSED}
EVENTS_QOS = 1000
DEFAULT_TIMEOUT_S = 20.0
QUIET_S = 1.5    # DDS discovery takes about this: no need to say it


def parse(argv) -> argparse.Namespace:
    """The command; ``--timeout`` before or after it."""
    timeout = argparse.ArgumentParser(add_help=False)
    timeout.add_argument('--timeout', type=float, default=argparse.SUPPRESS,
                         help=f'seconds to wait for the arm and its answer '
                              f'(default {DEFAULT_TIMEOUT_S:g})')
    parser = argparse.ArgumentParser(prog='arm', description=__doc__.split('\n\n')[0],
                                     parents=[timeout])
    commands = parser.add_subparsers(dest='command', required=True)
    goal = commands.add_parser('goal', help='a point in arm_base (m)', parents=[timeout])
    goal.add_argument('x', type=float)
    goal.add_argument('y', type=float)
    preset = commands.add_parser('preset', help='a preset by name', parents=[timeout])
    preset.add_argument('name')
    for sub in (goal, preset):
        sub.add_argument('--reach', action='store_true', help='wait until the goal is reached')
    for name in ('estop', 'reset', 'cancel'):
        commands.add_parser(name, help=f'call controller/{name}', parents=[timeout])
    commands.add_parser('state', help="the controller's state and the joint angles",
                        parents=[timeout])
    args = parser.parse_args(argv)
    args.timeout = getattr(args, 'timeout', DEFAULT_TIMEOUT_S)
    return args


class ArmClient(Node):
    """What the tool hears: the arm's state, its joints and the controller's events."""

    def __init__(self):
        super().__init__('arm_cli', start_parameter_services=False)
        self.state, self.joints = None, None
        self.events = []
        self.goal_pub = self.create_publisher(PointStamped, 'goal_point', COMMANDS)
        self.preset_pub = self.create_publisher(String, 'goal_preset', COMMANDS)
        self.events_sub = self.create_subscription(
            String, 'controller/events', lambda msg: self.events.append(msg.data), EVENTS_QOS)
        self.create_subscription(String, 'arm_state', self.on_state, LATCHED)
        self.create_subscription(JointState, 'joint_states', self.on_joints, STATE_STREAM)

    def on_state(self, msg: String) -> None:
        self.state = msg.data

    def on_joints(self, msg: JointState) -> None:
        self.joints = dict(zip(msg.name, msg.position))

    def spin_until(self, condition, deadline: float) -> bool:
        while not condition() and time.monotonic() < deadline:
            rclpy.spin_once(self, timeout_sec=0.05)
        return bool(condition())

    def ready_for_goals(self) -> bool:
        """The controller hears our goals and tells us its events."""
        return (self.goal_pub.get_subscription_count() > 0
                and self.preset_pub.get_subscription_count() > 0
                and self.events_sub.get_publisher_count() > 0)


def send_goal(node: ArmClient, args, deadline: float) -> int:
    if not node.spin_until(node.ready_for_goals, min(deadline, time.monotonic() + QUIET_S)):
        print('waiting for the controller ...', flush=True)
        if not node.spin_until(node.ready_for_goals, deadline):
            print(f'no answer: the controller did not appear within {args.timeout:g} s '
                  '(is the arm running on this ROS_DOMAIN_ID?)')
            return NO_ANSWER
    node.events.clear()
    if args.command == 'goal':
        msg = PointStamped()
        msg.header.frame_id = FRAME_ID
        msg.header.stamp = node.get_clock().now().to_msg()
        msg.point.x, msg.point.y = args.x, args.y
        node.goal_pub.publish(msg)
    else:
        node.preset_pub.publish(String(data=args.name))
    answer = wait_for_event(node, ANSWERS, deadline)
    if answer is None:
        print(f'no answer from the controller within {args.timeout:g} s')
        return NO_ANSWER
    code, sentence = answer
    print(sentence)
    if code != DONE or not args.reach:
        return code
    end = wait_for_event(node, ENDS, deadline)
    if end is None:
        print(f'not reached within {args.timeout:g} s (state: {node.state})')
        return NO_ANSWER
    print(end[1])
    return end[0]


def wait_for_event(node: ArmClient, kinds: dict, deadline: float):
    """(exit code, sentence) of the first event of ``kinds``, or None by the deadline."""
    found = []

    def heard() -> bool:
        while node.events and not found:
            kind, _, sentence = parse_event(node.events.pop(0))
            if kind in kinds:
                found.append((kinds[kind], f'{kind}: {sentence}'))
        return bool(found)
    return found[0] if node.spin_until(heard, deadline) else None


def call_service(node: ArmClient, name: str, deadline: float, timeout_s: float) -> int:
    client = node.create_client(Trigger, f'controller/{name}')
    if not node.spin_until(client.service_is_ready, deadline):
        print(f'no answer: controller/{name} did not appear within {timeout_s:g} s')
        return NO_ANSWER
    future = client.call_async(Trigger.Request())
    if not node.spin_until(future.done, deadline):
        print(f'no answer from controller/{name} within {timeout_s:g} s')
        return NO_ANSWER
    result = future.result()
    print(f"{name}: {'done' if result.success else 'refused'}: {result.message}")
    return DONE if result.success else REFUSED


def show_state(node: ArmClient, deadline: float, timeout_s: float) -> int:
    node.spin_until(lambda: node.state is not None and node.joints is not None, deadline)
    if node.state is None:
        print(f'no answer: no arm_state within {timeout_s:g} s')
        return NO_ANSWER
    print(f'state: {node.state}')
    if node.joints:
        print('joints: ' + ', '.join(f'{name} {value:+.3f} rad ({math.degrees(value):+.1f} deg)'
                                     for name, value in node.joints.items()))
    return DONE


def main(argv=None) -> int:
    argv = sys.argv if argv is None else argv
    args = parse(remove_ros_args(argv)[1:])
    use_udp_transport()
    rclpy.init(args=argv)
    node = ArmClient()
    deadline = time.monotonic() + args.timeout
    try:
        if args.command in ('goal', 'preset'):
            return send_goal(node, args, deadline)
        if args.command == 'state':
            return show_state(node, deadline, args.timeout)
        return call_service(node, args.command, deadline, args.timeout)
    except KeyboardInterrupt:
        return NO_ANSWER
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def entry() -> None:
    sys.exit(main())


if __name__ == '__main__':
    entry()
