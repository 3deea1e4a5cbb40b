"""The ``recorder`` node: records a run for plotting, until stopped (Ctrl-C).

Subscribes ``joint_states``, ``sim/ground_truth``, ``controller/setpoint`` (when it is
published), ``voltage_command`` and ``arm_state``; writes ``output_path`` (.npz, or .csv)
every ``flush_period_s`` and on the way out. Times are the messages' header stamps where
they have one, else the time of arrival, both on this node's clock. Plot the file with
``ros2 run arm_control plot_run /tmp/arm_run.npz``.
"""

import math
import sys

from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String

from arm_control.nodes import messages
from arm_control.nodes.common import COMMANDS, declare_parameters, LATCHED, run, STATE_STREAM
from arm_control.parameters import ParameterError
from arm_control.visual.recording import Recording


class RecorderNode(Node):

    def __init__(self):
        super().__init__('recorder')
        params = declare_parameters(self, 'recorder')
        self.output_path = params.get('output_path')
        flush_period_s = params.get('flush_period_s')
        if not isinstance(self.output_path, str) or not self.output_path:
            raise ParameterError(f"parameter 'output_path' = {self.output_path!r}: "
                                 'expected a file name (.npz or .csv)')
        if isinstance(flush_period_s, bool) or not isinstance(flush_period_s, (int, float)) \
                or not math.isfinite(flush_period_s) or flush_period_s <= 0.0:
            raise ParameterError(f"parameter 'flush_period_s' = {flush_period_s!r}: "
                                 'must be > 0')
        self.recording = Recording()
        self.saved_count = 0
        for topic, stream in (('joint_states', 'measured'), ('sim/ground_truth', 'truth'),
                              ('controller/setpoint', 'setpoint')):
            self.create_subscription(JointState, topic,
                                     lambda msg, stream=stream: self.on_joints(stream, msg),
                                     STATE_STREAM)
        self.create_subscription(Float64MultiArray, 'voltage_command', self.on_voltage,
                                 COMMANDS)
        self.create_subscription(String, 'arm_state', self.on_state, LATCHED)
        self.create_timer(float(flush_period_s), self.save)
        self.get_logger().info(f'recording to {self.output_path}')

    def _time_s(self, header=None) -> float:
        if header is not None and (header.stamp.sec or header.stamp.nanosec):
            return header.stamp.sec + 1e-9 * header.stamp.nanosec
        return self.get_clock().now().nanoseconds * 1e-9

    def on_joints(self, stream: str, msg: JointState) -> None:
        position = messages.joint_pair(msg) or []
        if len(position) < 2 or not messages.finite(position[:2]):
            self.get_logger().warning(f'{stream}: position {list(msg.position)} not recorded: '
                                      'expected 2 finite angles', throttle_duration_sec=2.0)
            return
        velocity = messages.joint_pair(msg, 'velocity') or []
        self.recording.add_joints(stream, self._time_s(msg.header), position, velocity)

    def on_voltage(self, msg: Float64MultiArray) -> None:
        if len(msg.data) != 2 or not messages.finite(list(msg.data)):
            self.get_logger().warning(f'voltage_command {list(msg.data)} not recorded: '
                                      'expected [shoulder_V, elbow_V]', throttle_duration_sec=2.0)
            return
        self.recording.add_voltage(self._time_s(), msg.data)

    def on_state(self, msg: String) -> None:
        self.recording.add_state(self._time_s(), msg.data)

    def save(self) -> None:
        if len(self.recording) == self.saved_count:
            return
        try:
            self.recording.save(self.output_path)
            self.saved_count = len(self.recording)
        except OSError as error:
            self.get_logger().error(f'cannot write {self.output_path}: {error}',
                                    throttle_duration_sec=10.0)

    def on_shutdown(self) -> None:
        self.save()
        self.get_logger().info(f'{len(self.recording)} samples in {self.output_path}')


def main(args=None):
    sys.exit(run(RecorderNode, args))


if __name__ == '__main__':
    main()
