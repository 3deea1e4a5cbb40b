"""The controller's core in closed loop with the simulated arm, for the core's tests: the rig
(``ClosedLoop`` with the kinematics for the assertions) and what the tests read of it."""

import math

import numpy as np

from arm_control.control.closed_loop import ClosedLoop
from arm_control.control.sensing import SensorReading
from arm_control.model.kinematics import TwoLinkKinematics

START = (1.5708, -1.5708)        # the sim's default: upper arm up, forearm level forward
DEG = math.pi / 180.0


class Rig(ClosedLoop):
    """The closed loop, with the kinematics for the assertions."""

    def __init__(self, arm, controller_config, planner=None, start=START, seed=0):
        super().__init__(arm, controller_config, planner, start, seed)
        self.kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)


def kinds(core, since=0):
    """The kinds of the events the core has said (since the ``since``-th)."""
    return [event.kind for event in list(core.events.history)[since:]]


def reached(core):
    return core.goals.counts['reached']


def goal_q_error(rig):
    return np.abs(rig.true_q - rig.core.last_step.goal_q)


def reading_at(q, velocity=(0.0, 0.0)):
    return SensorReading(tuple(q), tuple(velocity), (math.nan, math.nan))


def drive(core, t, readings, period=0.02):
    """Step ``core`` with ``readings``; return the time after and the voltages."""
    voltages = []
    for reading in readings:
        voltages.append(core.step(t, reading).volts)
        t += period
    return t, voltages


def drift(start, offset_rad, steps, period=0.02):
    """Readings of the shoulder sliding away from ``start`` by ``offset_rad`` in ``steps``
    periods, then staying there."""
    rate = offset_rad / (steps * period)
    return [reading_at((start[0] + offset_rad * k / steps, start[1]), (rate, 0.0))
            for k in range(1, steps + 1)]


def still(q, count):
    return [reading_at(q)] * count


def run(core, plant, seconds, period_s, sensors=True, until=None):
    """Step core and plant together; returns the times of the steps."""
    times = []
    for _ in range(round(seconds / period_s)):
        reading = plant.read() if sensors else None
        voltage = core.step(plant.time_s, reading).volts
        times.append((plant.time_s, np.array(voltage)))
        plant.set_voltage(voltage)
        plant.advance(period_s)
        if until is not None and until():
            break
    return times
