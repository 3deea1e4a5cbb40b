"""The ``recorder`` node: records a run as a rosbag2 bag (MCAP), until stopped (Ctrl-C).

Records ``joint_states``, ``sim/ground_truth``, ``controller/setpoint``, ``voltage_command``,
``arm_state``, ``battery_state`` and ``motor_currents``, each from its first message, into
the directory ``output_dir`` (empty: ``arm_run_<date-time>`` in the working directory), as
``ros2 bag record -s mcap`` would: the messages as they came off the wire, stamped with the
time they arrived. Everything recorded reaches the disk every ``flush_period_s``. Then:

    ros2 bag info arm_run                       # or open arm_run_0.mcap in Foxglove/PlotJuggler
    ros2 run arm_control plot_run arm_run       # arm_run.png
"""

import sys
import time

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64MultiArray, String

from arm_control.config import RecorderConfig
from arm_control.logs.bag import BagError, BagWriter, qos_duration
from arm_control.nodes.common import COMMANDS, declare_parameters, LATCHED, run, STATE_STREAM
from arm_control.parameters import ParameterError

# Best effort matches a publisher of either reliability: the sim's electrical topics are
# recorded whichever QoS it gives them.
ANY_PUBLISHER = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
RECORDED = (   # (topic relative to the node's namespace, type, QoS)
    ('joint_states', JointState, STATE_STREAM),
    ('sim/ground_truth', JointState, STATE_STREAM),
    ('controller/setpoint', JointState, STATE_STREAM),
    ('voltage_command', Float64MultiArray, COMMANDS),
    ('arm_state', String, LATCHED),
    ('battery_state', BatteryState, ANY_PUBLISHER),
    ('motor_currents', Float64MultiArray, ANY_PUBLISHER),
)


def type_name(msg_type) -> str:
    """'sensor_msgs/msg/JointState' for sensor_msgs.msg.JointState."""
    return f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"


def offered_qos(profile) -> dict:
    """A publisher's QoS as rosbag2 (metadata version 9) writes it."""
    return {
        'history': profile.history.short_key,
        'depth': profile.depth,
        'reliability': profile.reliability.short_key,
        'durability': profile.durability.short_key,
        'deadline': qos_duration(profile.deadline.nanoseconds),
        'lifespan': qos_duration(profile.lifespan.nanoseconds),
        'liveliness': profile.liveliness.short_key,
        'liveliness_lease_duration': qos_duration(profile.liveliness_lease_duration.nanoseconds),
        'avoid_ros_namespace_conventions': profile.avoid_ros_namespace_conventions,
    }


class RecorderNode(Node):

    def __init__(self):
        super().__init__('recorder')
        settings = RecorderConfig.from_parameters(declare_parameters(self, 'recorder'))
        output_dir = settings.output_dir or time.strftime('arm_run_%Y_%m_%d-%H_%M_%S')
        try:
            self.bag = BagWriter(output_dir)
        except BagError as error:
            raise ParameterError(f"parameter 'output_dir' = {output_dir!r}: {error}") from error
        for topic, msg_type, qos in RECORDED:
            name = self.resolve_topic_name(topic)        # as the bag names it: /arm1/...
            self.create_subscription(
                msg_type, topic, lambda data, info, name=name, msg_type=msg_type:
                self.on_message(name, msg_type, data, info), qos, raw=True)
        self.create_timer(settings.flush_period_s, self.flush)
        self.get_logger().info(f'recording to the bag {self.bag.path}')

    def on_message(self, topic: str, msg_type, data: bytes, info: dict) -> None:
        """As rosbag2 records: the receive time (rmw's, else now) and the source time."""
        if topic not in self.bag.topics:
            publishers = self.get_publishers_info_by_topic(topic)
            self.bag.add_topic(topic, type_name(msg_type),
                               [offered_qos(p.qos_profile) for p in publishers])
            self.get_logger().info(f'recording {topic}')
        receive_ns = info.get('received_timestamp') or self.get_clock().now().nanoseconds
        self.bag.write(topic, data, receive_ns, info.get('source_timestamp') or receive_ns)

    def flush(self) -> None:
        try:
            self.bag.flush()
        except OSError as error:
            self.get_logger().error(f'cannot write the bag {self.bag.path}: {error}',
                                    throttle_duration_sec=10.0)

    def on_shutdown(self) -> None:
        try:
            self.bag.close()
        except OSError as error:
            self.get_logger().error(f'cannot finish the bag {self.bag.path}: {error}')
            return
        self.get_logger().info(f'{self.bag.message_count} messages on {len(self.bag.topics)} '
                               f'topics in the bag {self.bag.path}')


def main(args=None):
    sys.exit(run(RecorderNode, args))


if __name__ == '__main__':
    sys.exit(main())
