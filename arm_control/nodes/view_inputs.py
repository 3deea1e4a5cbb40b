"""What the ``viewer`` and the ``markers`` nodes draw, taken into their ``ViewerModel``:
``joint_states``, ``controller/setpoint``, ``arm_state``, ``planned_path`` and
``goal_point``. A message the model refuses is said, throttled, and drawn as before."""

from geometry_msgs.msg import PointStamped
from nav_msgs.msg import Path
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from arm_control.nodes import messages
from arm_control.nodes.common import COMMANDS, LATCHED, STATE_STREAM


class ViewInputs:
    """Subscribes ``node`` to what ``model`` draws; ``on_reading(now_s)`` after each reading
    the model took."""

    def __init__(self, node, model, on_reading=None):
        self.node, self.model, self.on_reading = node, model, on_reading
        node.create_subscription(JointState, 'joint_states', self.on_joint_states, STATE_STREAM)
        node.create_subscription(JointState, 'controller/setpoint', self.on_setpoint,
                                 STATE_STREAM)
        node.create_subscription(String, 'arm_state', self.on_state, LATCHED)
        node.create_subscription(Path, 'planned_path', self.on_path, LATCHED)
        node.create_subscription(PointStamped, 'goal_point', self.on_goal, COMMANDS)

    def now_s(self) -> float:
        """The node's clock (simulated time with use_sim_time), in seconds."""
        return self.node.get_clock().now().nanoseconds * 1e-9

    def _refused(self, why) -> None:
        if why:
            self.node.get_logger().warning(why, throttle_duration_sec=2.0)

    def on_joint_states(self, msg: JointState) -> None:
        now_s = self.now_s()
        why = self.model.on_joint_state(messages.joint_pair(msg) or [], now_s)
        self._refused(why)
        if why is None and self.on_reading is not None:
            self.on_reading(now_s)

    def on_setpoint(self, msg: JointState) -> None:
        self._refused(self.model.on_setpoint(messages.joint_pair(msg) or []))

    def on_state(self, msg: String) -> None:
        self.model.on_state(msg.data)

    def on_path(self, msg: Path) -> None:
        self._refused(self.model.on_path(messages.poses_of(msg)))

    def on_goal(self, msg: PointStamped) -> None:
        why = self.model.on_goal(msg.point.x, msg.point.y, msg.point.z, msg.header.frame_id)
        if why:
            self.node.get_logger().info(f'not shown as queued: {why}',
                                        throttle_duration_sec=2.0)
