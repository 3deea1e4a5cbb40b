"""The ``markers`` node: the arm as a ``visualization_msgs/MarkerArray`` on ``arm_markers``.

For RViz users (frame ``arm_base``): the links in the state machine's colour, the joints,
the trajectory setpoint, the planned path, the queued goals, the forbidden regions and the
reachable annulus. Subscribes the same topics as the ``viewer``; publishes on each
``joint_states`` message, at most ``max_rate_hz`` times a second. With the URDF and
``robot_state_publisher`` RViz shows the links as a robot model too.
"""

import math
import sys

from rclpy.node import Node
from visualization_msgs.msg import MarkerArray

from arm_control.config import ArmConfig
from arm_control.nodes.common import declare_parameters, run, STATE_STREAM
from arm_control.nodes.view_inputs import ViewInputs
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
        self.inputs = ViewInputs(self, self.model, self.publish_markers)

    def publish_markers(self, now_s: float) -> None:
        if now_s - self.last_publish_s >= self.min_period_s:
            self.last_publish_s = now_s
            self.markers_pub.publish(self.builder.build(self.model.scene(now_s),
                                                        self.get_clock().now().to_msg()))


def main(args=None):
    sys.exit(run(MarkersNode, args))


if __name__ == '__main__':
    main()
