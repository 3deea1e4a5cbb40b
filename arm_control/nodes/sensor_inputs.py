"""The controller's readings: ``joint_states``, ``motor_encoders`` (JointState) and
``battery_state`` (bus volts and current, for the estimate and the feedforward).

All three are taken in the loop's thread, at its tick (and, in simulated time, while it
waits for a step's reading): no executor waits on them (``Drained``), so the executor does
not wake for each, and no thread takes from a subscription another waits on (rcl does not
promise that: a controller doing so died of a corrupted heap). They are handled in the order
they arrived: a robot sends the encoders and the bus first, and a joint_states goes with
those that came before it.
"""

import math

from sensor_msgs.msg import BatteryState, JointState

from arm_control.control.sensing import SensorReading
from arm_control.nodes import messages
from arm_control.nodes.common import (Drained, guarded, listen, NodePart, STATE_STREAM,
                                      take_all)

# A reading is timed at its stamp when that is at most this long before its arrival, and
# not after it (the stamp on this host's clock); else at its arrival.
STAMP_TRUSTED_S = 0.05
READINGS_KEPT = 4                 # joint_states kept for the next tick, the latest last
MAX_ANGLE_RAD = 4.0 * math.pi     # no sensor of this arm reads beyond two turns


class SensorInputs(NodePart):
    """The readings since the last tick (``take_new``), each with when it is taken to be."""

    def __init__(self, node):
        self.node = node
        # The latest readings for the loop, and the encoders and bus: (value, received at).
        self.readings, self.encoders, self.bus = [], None, None
        self.reading_ages_s = []            # arrival minus stamp of each joint_states
        # The encoders and the bus first: a robot sends them before its joint states, so at one
        # instant of arrival they go with it.
        self.inputs = [(listen(node, kind, topic, handler, STATE_STREAM, Drained()), handler)
                       for topic, kind, handler in (
                           ('motor_encoders', JointState, self.on_encoders),
                           ('battery_state', BatteryState, self.on_battery),
                           ('joint_states', JointState, self.on_joint_states))]
        self.joint_states_sub = self.inputs[-1][0]

    def take_new(self) -> list:
        """In the loop's thread: the readings since the last call, oldest first."""
        self.take_arrived()
        readings, self.readings = self.readings, []
        return readings

    def has_reading(self, now_s: float) -> bool:
        """The joint states of ``now_s`` (simulated time: the sim's step) are in."""
        self.take_arrived()
        return any(taken >= now_s - 1e-6 for _, taken in self.readings)

    @guarded
    def take_arrived(self) -> None:
        """In the loop's thread: what waits in the three readers, in the order it arrived, so
        that each joint_states goes with the encoders and the bus that came before it (two
        readings can wait for one tick)."""
        arrived = []
        for order, (subscription, handler) in enumerate(self.inputs):
            take_all(subscription, lambda msg, received_ns, order=order, handler=handler:
                     arrived.append((received_ns, order, handler, msg)), received=True)
        for received_ns, _, handler, msg in sorted(arrived, key=lambda taken: taken[:2]):
            handler(msg, received_ns)

    @guarded
    def on_joint_states(self, msg: JointState, received_ns: int = 0) -> None:
        if not self.node.loop.started():
            return                                  # the sim's clock is not there yet
        sensing = self.node.core.sensing
        sensing.refuse_leaps |= self.joint_states_sub.get_publisher_count() > 1
        pair = messages.joint_readings(msg, MAX_ANGLE_RAD, sensing.max_leap_speed_rad_s)
        if isinstance(pair, str):
            return self.node.warn_bad(f'ignored joint_states: {pair}')
        position, velocity = pair
        now = self.node.loop.arrived_s(received_ns)
        stamp = self.node.loop.guard.to_control_s(messages.stamp_s(msg.header))
        age_s = now - stamp
        if math.isfinite(age_s):
            self.reading_ages_s.append(age_s)

        def fresh(latest, missing):
            return latest[0] if latest is not None and \
                now - latest[1] <= self.node.config.joint_state_timeout_s else missing
        encoder = fresh(self.encoders, (math.nan, math.nan))
        bus, supply_current = fresh(self.bus, (math.nan, math.nan))
        # Taken at its stamp, when the sensors were read: timed at its arrival the estimate
        # would lag the arm by the motion of the transit, and the feedback push it ahead. In
        # simulated time the stamp is the clock's, which may not have reached it yet, or have
        # jumped since.
        trusted = 0.0 <= age_s <= STAMP_TRUSTED_S or (
            self.node.loop.simulated() and abs(age_s) <= self.node.config.joint_state_timeout_s)
        taken = stamp if trusted else now
        # All since the last tick: beside a second publisher the latest was often its.
        self.readings = self.readings[-(READINGS_KEPT - 1):] + [(SensorReading(
            tuple(position), tuple(velocity), tuple(encoder), stamp, bus, supply_current), taken)]

    @guarded
    def on_encoders(self, msg: JointState, received_ns: int = 0) -> None:
        position = messages.joint_pair(msg, 'position')
        if position is None or not messages.within(position, MAX_ANGLE_RAD):
            return self.node.warn_bad('ignored motor_encoders: expected finite positions '
                                      'of [shoulder, elbow] within two turns')
        self.encoders = (position, self.node.loop.arrived_s(received_ns))

    @guarded
    def on_battery(self, msg: BatteryState, received_ns: int = 0) -> None:
        if not 0.0 < msg.voltage <= 2.0 * self.node.arm.battery.nominal_voltage:   # NaN too
            return self.node.warn_bad(f'ignored battery_state: voltage {msg.voltage} V')
        # BatteryState's current is negative while discharging; NaN when not reported.
        self.bus = ((float(msg.voltage), -float(msg.current)),
                    self.node.loop.arrived_s(received_ns))
