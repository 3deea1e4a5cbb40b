"""The ``tour`` node: visits goals one by one and reports how each move went.

Starts once the controller's diagnostics say its client reaches the planner (a goal sent
before would be rejected). Publishes each goal as a ``goal_point`` (PointStamped in arm_base),
waits for the controller's ``arm_state`` to settle in ``holding`` (or to refuse the goal), and
logs the move time and the error the arm is held at, measured on ``/sim/ground_truth``
``hold_check_s`` after arrival: by then the arm is still, so a true state that reaches this
node late cannot skew it. It is the demonstration the README's first command runs; with ROS
installed, ``ros2 run arm_control tour`` does the same. Its exit code is the number of goals
not reached (0: every one).
"""

import math
import sys

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from arm_control.config import ArmConfig, FRAME_ID
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.nodes.common import (COMMANDS, controller_sees_planner, declare_parameters,
                                      LATCHED, run, STATE_STREAM)
from arm_control.parameters import ParameterError

FINISHED, REFUSED = 'holding', ('error', 'estopped', 'disabled')
MAX_EXIT_CODE = 100             # the exit code: goals not reached, up to this


class TourNode(Node):

    def __init__(self):
        super().__init__('tour')
        params = declare_parameters(self, 'tour')
        self.arm = ArmConfig.from_parameters(params)
        self.kinematics = TwoLinkKinematics(self.arm.shoulder.length_m, self.arm.elbow.length_m)
        names = [n for n in params['goals'] if n]
        presets = {name: (x, y) for name, x, y in self.arm.presets}
        unknown = [n for n in names if n not in presets]
        if unknown:
            raise ParameterError(f"parameter 'goals' = {names}: {unknown} are not presets "
                                 f'{list(presets)}')
        self.goals = [(name, presets[name]) for name in names]
        self.loops = int(params['loops'])
        self.goal_timeout_s = float(params['goal_timeout_s'])
        self.hold_check_s = float(params['hold_check_s'])
        self.state = ''
        self.true_q = None
        self.results = []                            # (reached, line) per goal
        self.exit_code = 0
        self.index, self.loop = -1, 0
        self.sent_at = None
        self.arrived_after_s = None                  # the move time, once holding
        self.left_start_state = False
        self.planner_seen = False                    # by the controller, from its diagnostics
        self.goal_pub = self.create_publisher(PointStamped, 'goal_point', COMMANDS)
        self.create_subscription(String, 'arm_state', self.on_state, LATCHED)
        self.create_subscription(JointState, 'sim/ground_truth', self.on_truth, STATE_STREAM)
        # /diagnostics is shared by every arm: listen to this namespace's controller.
        self.controller_name = f"{self.get_namespace().rstrip('/')}/controller"
        self.create_subscription(DiagnosticArray, '/diagnostics', self.on_diagnostics, 10)
        self.create_timer(0.05, self.tick)

    def now_s(self) -> float:
        """The node's clock (simulated time with use_sim_time), in seconds."""
        return self.get_clock().now().nanoseconds * 1e-9

    def on_state(self, msg: String) -> None:
        if msg.data != self.state:
            self.left_start_state = True
            self.arrived_after_s = None              # a hold that ends early is no arrival
        self.state = msg.data

    def on_truth(self, msg: JointState) -> None:
        if len(msg.position) == 2:
            self.true_q = tuple(msg.position)

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        seen = controller_sees_planner(msg, self.controller_name)
        if seen is not None:
            self.planner_seen = seen

    def tick(self) -> None:
        if (self.true_q is None or self.state in ('', 'no_sensors')
                or self.goal_pub.get_subscription_count() == 0
                or (self.sent_at is None and not self.planner_seen)):
            return                                   # the arm is not up yet
        if self.sent_at is None:
            self.send_next()
            return
        elapsed = self.now_s() - self.sent_at
        name, goal = self.goals[self.index]
        if self.left_start_state and self.state == FINISHED:
            if self.arrived_after_s is None:
                self.arrived_after_s = elapsed
            elif elapsed >= self.arrived_after_s + self.hold_check_s:
                x, y = self.kinematics.forward(self.true_q)
                error_mm = 1000.0 * math.hypot(x - goal[0], y - goal[1])
                self.report(name, goal, f'reached in {self.arrived_after_s:.2f} s, held '
                                        f'{error_mm:.1f} mm from the goal', reached=True)
        elif self.left_start_state and self.state in REFUSED:
            self.report(name, goal, f'not reached: controller went to {self.state}')
        elif elapsed > self.goal_timeout_s:
            self.report(name, goal, f'not reached within {self.goal_timeout_s:g} s')

    def report(self, name, goal, outcome: str, reached: bool = False) -> None:
        line = f'{name:>14} ({goal[0]:+.2f}, {goal[1]:+.2f}) m: {outcome}'
        self.results.append((reached, line))
        self.get_logger().info(line)
        self.send_next()

    def send_next(self) -> None:
        self.index += 1
        if self.index == len(self.goals):
            self.index, self.loop = 0, self.loop + 1
            if self.loops and self.loop >= self.loops:
                missed = sum(not reached for reached, _ in self.results)
                self.exit_code = min(missed, MAX_EXIT_CODE)
                self.get_logger().info(
                    f'tour finished: {len(self.results) - missed} of {len(self.results)} goals '
                    'reached\n' + '\n'.join(line for _, line in self.results))
                self.context.try_shutdown()          # ends spin(); main() cleans up
                return
        name, (x, y) = self.goals[self.index]
        msg = PointStamped()
        msg.header.frame_id = FRAME_ID
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.point.x, msg.point.y = float(x), float(y)
        self.left_start_state, self.arrived_after_s = False, None
        self.goal_pub.publish(msg)
        self.sent_at = self.now_s()
        self.get_logger().info(f'goal {name}: ({x:+.2f}, {y:+.2f}) m')


def main(args=None):
    sys.exit(run(TourNode, args))


if __name__ == '__main__':
    main()
