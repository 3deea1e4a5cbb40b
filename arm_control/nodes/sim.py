"""The ``sim`` node: motor voltages in, the arm's sensors out.

Subscribes ``voltage_command`` (Float64MultiArray [shoulder_V, elbow_V]) and ``~/set_state``
(JointState: put the arm at a position and velocity); publishes ``joint_states``
(potentiometers), ``motor_encoders``, ``~/ground_truth`` and ``/diagnostics``; serves
``~/reset`` (Trigger: back to ``initial_position`` at rest).
"""

import math
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header
from std_srvs.srv import Trigger

from arm_control.config import ArmConfig, JOINT_NAMES, SimConfig
from arm_control.model.plant import ArmPlant
from arm_control.nodes.common import (COMMANDS, declare_parameters, finite, run,
                                      STATE_STREAM, status)

# After a stall (a paused process, a loaded machine) the physics catches up at most this far.
MAX_CATCH_UP_S = 0.1


class SimNode(Node):

    def __init__(self):
        super().__init__('sim')
        params = declare_parameters(self, 'sim')
        self.arm = ArmConfig.from_parameters(params)
        self.config = SimConfig.from_parameters(params)
        seed = None if self.config.random_seed < 0 else self.config.random_seed
        self.plant = ArmPlant(self.arm, self.config.initial_position,
                              self.config.physics_step_s, seed)
        if self.config.rest_until_first_command:
            self.plant.rest()
        self.last_command_time = -math.inf
        self.commands_rejected = 0
        self.commands_rejected_reported = 0
        self.timed_out = True

        self.joint_states_pub = self.create_publisher(JointState, 'joint_states', STATE_STREAM)
        self.encoders_pub = self.create_publisher(JointState, 'motor_encoders', STATE_STREAM)
        self.truth_pub = self.create_publisher(JointState, '~/ground_truth', STATE_STREAM)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(Float64MultiArray, 'voltage_command', self.on_voltage, COMMANDS)
        self.create_subscription(JointState, '~/set_state', self.on_set_state, COMMANDS)
        self.create_service(Trigger, '~/reset', self.on_reset)

        self.period_s = 1.0 / self.config.publish_rate_hz
        self.last_step = time.monotonic()
        self.tick_periods_s = []
        self.create_timer(self.period_s, self.step)
        self.create_timer(1.0, self.publish_diagnostics)
        self.get_logger().info(
            f'simulating the arm at {self.config.publish_rate_hz:g} Hz from '
            f'[{self.config.initial_position[0]:.3f}, {self.config.initial_position[1]:.3f}] rad')

    def on_voltage(self, msg: Float64MultiArray) -> None:
        voltage = list(msg.data)
        if len(voltage) != 2 or not finite(voltage):
            self.commands_rejected += 1
            self.get_logger().warning(
                f'rejected voltage_command {voltage}: expected [shoulder_V, elbow_V], finite; '
                'keeping the last good command', throttle_duration_sec=1.0)
            return
        self.plant.set_voltage(voltage)
        if self.plant.resting:
            self.plant.release()
            self.get_logger().info('first voltage command: the arm leaves its rest')
        self.last_command_time = time.monotonic()
        if self.timed_out:
            self.timed_out = False
            self.get_logger().info('voltage commands arriving')

    def on_set_state(self, msg: JointState) -> None:
        position = list(msg.position)
        velocity = list(msg.velocity) or [0.0, 0.0]
        if len(position) != 2 or len(velocity) != 2 or not finite(position + velocity):
            self.get_logger().warning(
                f'rejected set_state: expected 2 finite positions (and optionally 2 velocities),'
                f' got position={position} velocity={velocity}', throttle_duration_sec=1.0)
            return
        self.plant.reset(position, velocity)
        self.get_logger().info(f'arm set to position {position} rad, velocity {velocity} rad/s')

    def on_reset(self, request, response):
        self.plant.reset(self.config.initial_position)
        self.plant.set_voltage((0.0, 0.0))
        if self.config.rest_until_first_command:
            self.plant.rest()
        response.success = True
        response.message = f'arm at rest at {list(self.config.initial_position)} rad'
        self.get_logger().info(response.message)
        return response

    def step(self) -> None:
        now = time.monotonic()
        elapsed = min(now - self.last_step, MAX_CATCH_UP_S)
        self.tick_periods_s.append(now - self.last_step)
        self.last_step = now
        if now - self.last_command_time > self.config.command_timeout_s:
            if not self.timed_out:
                self.timed_out = True
                self.get_logger().warning(
                    f'no voltage_command for {self.config.command_timeout_s:g} s: applying 0 V')
            self.plant.set_voltage((0.0, 0.0))
        self.plant.advance(elapsed)
        self.publish(self.plant.read())

    def publish(self, reading) -> None:
        stamp = self.get_clock().now().to_msg()

        def joint_state(position, velocity, effort=()):
            return JointState(header=_header(stamp), name=list(JOINT_NAMES),
                              position=[float(p) for p in position],
                              velocity=[float(v) for v in velocity],
                              effort=[float(e) for e in effort])

        self.joint_states_pub.publish(joint_state(
            reading.potentiometer_rad, reading.velocity_rad_s, reading.effort_nm))
        self.encoders_pub.publish(joint_state(reading.encoder_rad,
                                              reading.encoder_velocity_rad_s))
        truth = reading.true_state
        self.truth_pub.publish(joint_state(truth[:2], truth[2:], reading.effort_nm))

    def publish_diagnostics(self) -> None:
        periods, self.tick_periods_s = self.tick_periods_s, []
        worst = max(periods, default=math.nan)
        mean = sum(periods) / len(periods) if periods else math.nan
        level = DiagnosticStatus.OK
        message = 'running'
        rejected_now = self.commands_rejected - self.commands_rejected_reported
        self.commands_rejected_reported = self.commands_rejected
        if rejected_now:
            level, message = DiagnosticStatus.WARN, f'{rejected_now} malformed voltage commands'
        if self.timed_out:
            level, message = DiagnosticStatus.WARN, 'no voltage commands: applying 0 V'
        if worst > 3 * self.period_s:
            level, message = DiagnosticStatus.WARN, f'loop stalled for {worst:.3f} s'
        diagnostic = DiagnosticArray()
        diagnostic.header.stamp = self.get_clock().now().to_msg()
        diagnostic.status = [status(self, level, message, {
            'mean period (s)': f'{mean:.4f}', 'worst period (s)': f'{worst:.4f}',
            'commands rejected': self.commands_rejected,
            'applied voltage (V)': list(self.plant.voltage),
        })]
        self.diagnostics_pub.publish(diagnostic)


def _header(stamp):
    return Header(stamp=stamp, frame_id='')


def main(args=None):
    sys.exit(run(SimNode, args))


if __name__ == '__main__':
    main()
