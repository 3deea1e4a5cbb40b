"""The ``markers`` node: the arm as a ``visualization_msgs/MarkerArray`` on ``arm_markers``.

For RViz users (frame ``arm_base``): the links in the state machine's colour, the joints,
the trajectory setpoint, the planned path, the queued goals, the forbidden regions and the
reachable annulus. Subscribes the same topics as the ``viewer``; publishes on each
``joint_states`` message, at most ``max_rate_hz`` times a second. With the URDF and
``robot_state_publisher`` RViz shows the links as a robot model too.
"""

import math
import sys

from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from arm_control.config import ArmConfig
from arm_control.nodes import messages
from arm_control.nodes.common import COMMANDS, declare_parameters, LATCHED, run, STATE_STREAM
from arm_control.parameters import ParameterError
from arm_control.visual.markers import MarkerBuilder
from arm_control.visual.viewer_model import ViewerModel


class MarkersNode(Node):

    def __init__(self):
        super().__init__('markers')
        params = declare_parameters(self, 'markers')
        self.arm = ArmConfig.from_parameters(params)
        max_rate_hz = params.get('max_rate_hz')
        if isinstance(max_rate_hz, bool) or not isinstance(max_rate_hz, (int, float)) \
                or not math.isfinite(max_rate_hz) or max_rate_hz <= 0.0:
            raise ParameterError(f"parameter 'max_rate_hz' = {max_rate_hz!r}: must be > 0")
        self.min_period_s = 1.0 / max_rate_hz
        self.last_publish_s = -math.inf
        self.model = ViewerModel(self.arm)
        self.builder = MarkerBuilder(self.arm)
        self.markers_pub = self.create_publisher(MarkerArray, 'arm_markers', STATE_STREAM)
        self.create_subscription(JointState, 'joint_states', self.on_joint_states, STATE_STREAM)
        self.create_subscription(JointState, 'controller/setpoint', self.on_setpoint,
                                 STATE_STREAM)
        self.create_subscription(String, 'arm_state', self.on_state, LATCHED)
        self.create_subscription(Path, 'planned_path', self.on_path, LATCHED)
        self.create_subscription(PointStamped, 'goal_point', self.on_goal, COMMANDS)

    def now_s(self) -> float:
        """The node's clock (simulated time with use_sim_time), in seconds."""
        return self.get_clock().now().nanoseconds * 1e-9

    def _refused(self, why) -> None:
        if why:
            self.get_logger().warning(why, throttle_duration_sec=2.0)

    def on_joint_states(self, msg: JointState) -> None:
        now = self.now_s()
        why = self.model.on_joint_state((messages.joint_pair(msg) or []), now)
        self._refused(why)
        if why is None and now - self.last_publish_s >= self.min_period_s:
            self.last_publish_s = now
            self.markers_pub.publish(self.builder.build(self.model.scene(now),
                                                        self.get_clock().now().to_msg()))

    def on_setpoint(self, msg: JointState) -> None:
        self._refused(self.model.on_setpoint((messages.joint_pair(msg) or [])))

    def on_state(self, msg: String) -> None:
        self.model.on_state(msg.data)

    def on_path(self, msg: Path) -> None:
        self._refused(self.model.on_path(messages.poses_of(msg)))

    def on_goal(self, msg: PointStamped) -> None:
        self.model.on_goal(msg.point.x, msg.point.y, msg.point.z, msg.header.frame_id)


def main(args=None):
    sys.exit(run(MarkersNode, args))


if __name__ == '__main__':
    main()
