"""The ROS messages of one robot reading (``frc.codec.Reading``), all with its one stamp."""

import math

from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64MultiArray, Header

from arm_control.config import JOINT_NAMES
from arm_control.frc.conversions import battery_state_current_a, joint_effort_nm


def reading_messages(reading, header: Header, dynamics) -> dict:
    """{'joint_states', 'motor_currents', 'motor_encoders', 'battery_state'}: what the
    reading measured (NaN fields leave their message out, or ``effort`` empty)."""
    current = reading.motor_current_a
    measured = all(map(math.isfinite, current))
    effort = list(joint_effort_nm(current, dynamics)) if measured else []
    messages = {'joint_states': JointState(
        header=header, name=list(JOINT_NAMES), position=list(reading.position_rad),
        velocity=list(reading.velocity_rad_s), effort=effort)}
    if measured:
        messages['motor_currents'] = Float64MultiArray(data=list(current))
    if all(map(math.isfinite, reading.encoder_rad)):
        messages['motor_encoders'] = JointState(header=header, name=list(JOINT_NAMES),
                                                position=list(reading.encoder_rad))
    if math.isfinite(reading.bus_voltage_v):
        messages['battery_state'] = battery_state(
            header, reading.bus_voltage_v, battery_state_current_a(reading.supply_current_a))
    return messages


def battery_state(header: Header, bus_voltage_v: float, current_a: float) -> BatteryState:
    """BatteryState with what the robot measures; the rest NaN, as the message asks."""
    return BatteryState(header=header, voltage=bus_voltage_v, current=current_a,
                        temperature=math.nan, charge=math.nan, capacity=math.nan,
                        design_capacity=math.nan, percentage=math.nan, present=True,
                        power_supply_status=BatteryState.POWER_SUPPLY_STATUS_DISCHARGING,
                        power_supply_technology=BatteryState.POWER_SUPPLY_TECHNOLOGY_UNKNOWN)


def age_summary(ages_ms) -> dict:
    """How old readings were when the bridge took them: p50, p99, max, and how many were
    older than 10 ms (the contract's bar), as /diagnostics values."""
    ages_ms = sorted(ages_ms)
    if not ages_ms:
        return {}
    return {'reading age p50 (ms, last s)': f'{ages_ms[len(ages_ms) // 2]:.2f}',
            'reading age p99 (ms, last s)':
                f'{ages_ms[min(len(ages_ms) - 1, int(0.99 * len(ages_ms)))]:.2f}',
            'reading age max (ms, last s)': f'{ages_ms[-1]:.2f}',
            'readings older than 10 ms (last s)': sum(a > 10.0 for a in ages_ms)}
