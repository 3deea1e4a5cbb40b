"""The sim's readings on their topics: ``motor_encoders``, ``~/ground_truth`` (each true state
since the last reading, at its instant), ``battery_state``, ``motor_currents``, then
``joint_states`` last, so that a controller reading it finds the encoders and the bus of the
same instant already there."""

import math

from rclpy.time import Time
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64MultiArray

from arm_control.nodes import messages
from arm_control.nodes.common import STATE_STREAM


class SensorTopics:
    """The publishers of one simulated arm's sensors."""

    def __init__(self, node):
        self.joint_states_pub = node.create_publisher(JointState, 'joint_states', STATE_STREAM)
        self.encoders_pub = node.create_publisher(JointState, 'motor_encoders', STATE_STREAM)
        self.truth_pub = node.create_publisher(JointState, '~/ground_truth', STATE_STREAM)
        self.battery_pub = node.create_publisher(BatteryState, 'battery_state', STATE_STREAM)
        self.currents_pub = node.create_publisher(Float64MultiArray, 'motor_currents',
                                                  STATE_STREAM)

    def publish(self, reading, origin_s: float, truths: list) -> None:
        """One instant's reading, stamped at ``origin_s`` (the clock's time at plant time 0)
        plus its time; ``truths``: (plant s, stamp s, state, effort) kept since the last."""
        stamp = Time(nanoseconds=round((origin_s + reading.time_s) * 1e9)).to_msg()
        self.encoders_pub.publish(messages.joint_state(stamp, reading.encoder_rad,
                                                       reading.encoder_velocity_rad_s))
        # The true states since the last reading, then the reading's, each at its instant.
        truths = [kept for kept in truths if kept[0] < reading.time_s - 1e-9]
        truths.append((reading.time_s, origin_s + reading.time_s, reading.true_state,
                       reading.effort_nm))
        for _, stamp_s, state, effort in truths:
            self.truth_pub.publish(messages.joint_state(
                Time(nanoseconds=round(stamp_s * 1e9)).to_msg(), state[:2], state[2:], effort))
        battery = BatteryState(header=messages.header(stamp, ''), present=True,
                               voltage=float(reading.bus_voltage),
                               current=-float(reading.supply_current_a))
        battery.power_supply_status = (BatteryState.POWER_SUPPLY_STATUS_CHARGING
                                       if reading.supply_current_a < 0.0 else
                                       BatteryState.POWER_SUPPLY_STATUS_DISCHARGING)
        for name in ('temperature', 'charge', 'capacity', 'design_capacity', 'percentage'):
            setattr(battery, name, math.nan)
        self.battery_pub.publish(battery)
        self.currents_pub.publish(Float64MultiArray(
            data=[float(i) for i in reading.motor_current_a]))
        self.joint_states_pub.publish(messages.joint_state(
            stamp, reading.potentiometer_rad, reading.velocity_rad_s, reading.effort_nm))
