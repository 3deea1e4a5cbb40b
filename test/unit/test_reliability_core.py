"""Fail-safe rules of the controller's core, in simulated time on the plant (no ROS).

- commanding ends within ``joint_state_timeout_s`` of the last reading, not a period later;
- an arm put elsewhere (a reset sim: the sensors leap) is held where it now is;
- an arm that cannot follow (a forearm far heavier than the model) is e-stopped by the
  tracking-error rule -- its fall is not mistaken for the arm having been put elsewhere;
- an arm frozen with its sensors (a paused simulator) mid-motion brakes from where it is and
  its goal is planned again from there.
"""

import dataclasses
import math

from controller_rig import run, START
import numpy as np

from arm_control import config
from arm_control.control.controller import ArmController
from arm_control.control.events import EventKind as Kind
from arm_control.control.sensing import SensorReading
from arm_control.control.state_machine import ArmState
from arm_control.model.plant import ArmPlant
from arm_control.model.world import ForbiddenSpace
from arm_control.planning.planner import Planner
from arm_control.plans.goals import GoalValidator
from arm_control.plans.port import plan_in_process


def test_commanding_ends_within_the_joint_state_timeout(arm, controller_config):
    core = ArmController(arm, controller_config)
    plant = ArmPlant(arm, START, seed=1)
    period_s = 1.0 / controller_config.loop_rate_hz
    run(core, plant, 0.5, period_s)
    last_reading_s = plant.time_s - period_s
    steps = run(core, plant, 0.5, period_s, sensors=False)
    commanding = [t for t, v in steps if np.any(v != 0.0)]
    # The last non-zero command is held one period: it must end within the timeout.
    assert commanding
    assert commanding[-1] + period_s - last_reading_s <= \
        controller_config.joint_state_timeout_s + 1e-9
    assert core.state == ArmState.NO_SENSORS
    assert Kind.SENSORS_LOST in [e.kind for e in core.events.take()]


def test_an_arm_put_elsewhere_is_held_there(arm, controller_config):
    core = ArmController(arm, controller_config)
    plant = ArmPlant(arm, START, seed=2)
    period_s = 1.0 / controller_config.loop_rate_hz
    run(core, plant, 0.5, period_s)
    elsewhere = (1.2, -1.0)                    # 22 deg and 33 deg away, in one sample
    plant.reset(elsewhere)
    run(core, plant, 2.0, period_s)
    assert core.state == ArmState.WAITING
    assert Kind.ARM_MOVED in [e.kind for e in core.events.take()]
    assert np.max(np.abs(np.array(plant.state[:2]) - elsewhere)) < math.radians(2.0)


def test_an_arm_that_cannot_follow_is_estopped(arm, controller_config):
    # 8x the model's forearm. (At 200 kg it falls faster than the current-limited motors
    # could ever drive it: that is a leap.)
    heavy = dataclasses.replace(arm, elbow=dataclasses.replace(arm.elbow, mass_kg=120.0))
    core = ArmController(arm, controller_config)           # its model: the 15 kg forearm
    plant = ArmPlant(heavy, START, seed=3)
    period_s = 1.0 / controller_config.loop_rate_hz
    run(core, plant, 3.0, period_s, until=lambda: core.state == ArmState.ESTOPPED)
    said = [e.kind for e in core.events.take()]
    assert core.state == ArmState.ESTOPPED, said
    assert Kind.CONTROL_FAILED in said and Kind.ARM_MOVED not in said
    # It fell under the heavy forearm before the rule fired, but no farther than needed:
    # past the limit (20 deg) for the rule's time (0.5 s) at the speed it fell.
    assert plant.time_s < 1.5


def test_an_arm_that_cannot_follow_is_estopped_however_many_goals_come(arm,
                                                                       controller_config):
    """The same heavy forearm, now moving to goals that keep coming (preempting, every
    0.2 s): leaving a plan it is far off, to plan again, must not keep the tracking-error
    rule from stopping an arm that cannot follow."""
    heavy = dataclasses.replace(arm, elbow=dataclasses.replace(arm.elbow, mass_kg=120.0))
    core = plan_in_process(ArmController(arm, controller_config),
                           Planner(arm, config.load('planner')[1]))
    plant = ArmPlant(heavy, START, seed=3)
    period_s = 1.0 / controller_config.loop_rate_hz
    for index in range(20):
        core.submit_goal(plant.time_s, (1.1, 0.9)[index % 2], (0.9, 1.1)[index % 2],
                         preempt=True)
        run(core, plant, 0.2, period_s, until=lambda: core.state == ArmState.ESTOPPED)
        if core.state == ArmState.ESTOPPED:
            break
    said = [e.kind for e in core.events.take()]
    assert core.state == ArmState.ESTOPPED, said
    assert Kind.CONTROL_FAILED in said
    assert plant.time_s < 3.0


def test_bunched_readings_are_not_a_leap(arm, controller_config):
    """On a loaded machine readings arrive late and together: taken 0.1 s apart, received
    a few ms apart. That is not the arm being put elsewhere: a heavy forearm that sinks while
    they arrive so is still e-stopped by the tracking-error rule."""
    heavy = dataclasses.replace(arm, elbow=dataclasses.replace(arm.elbow, mass_kg=120.0))
    core = ArmController(arm, controller_config)
    plant = ArmPlant(heavy, START, seed=4)
    period_s = 1.0 / controller_config.loop_rate_hz
    held = []                                   # (reading, taken at) not yet delivered
    for index in range(round(3.0 / period_s)):
        now = plant.time_s
        r = plant.read()
        held.append(SensorReading(r.potentiometer_rad, r.velocity_rad_s, r.encoder_rad, now))
        reading, received = None, None
        if index % 6 == 0:                      # the oldest of the burst, received now
            reading, received = held[0], now
        elif index % 6 == 1:                    # the newest, received 2 ms after it
            reading, received = held[-1], now - period_s + 0.002
            held = []
        voltage = core.step(now, reading, received).volts
        plant.set_voltage(voltage)
        plant.advance(period_s)
        if core.state == ArmState.ESTOPPED:
            break
    said = [e.kind for e in core.events.take()]
    assert core.state == ArmState.ESTOPPED, said
    assert Kind.CONTROL_FAILED in said and Kind.ARM_MOVED not in said


def test_a_stall_that_froze_the_arm_too_brakes_or_rejoins_then_reaches_the_goal(
        arm, controller_config):
    """A paused simulator freezes the arm with its sensors: 0 V while they are away. When
    they return with the arm moving, it brakes from where it is while the goal is planned
    again, where that straight line is free; here, over the top towards the floor behind,
    it is not, and the plan goes on from where the arm is on it. It stays out of the floor
    and gets there."""
    core = plan_in_process(ArmController(arm, controller_config),
                           Planner(arm, config.load('planner')[1]))
    plant = ArmPlant(arm, START, seed=5)
    period_s = 1.0 / controller_config.loop_rate_hz
    core.submit_goal(plant.time_s, -1.0, 1.0)                  # front to back, over the top
    run(core, plant, 2.0, period_s, until=lambda: core.state == ArmState.TRACKING)
    run(core, plant, 0.4, period_s)
    moving = np.array(plant.state)
    assert np.max(np.abs(moving[2:])) > 1.0
    clock_s = plant.time_s
    for _ in range(round(1.5 / period_s)):                      # frozen: no time for the arm
        core.step(clock_s, None)
        clock_s += period_s
    assert core.state == ArmState.NO_SENSORS
    lowest, offset = [], clock_s - plant.time_s
    for _ in range(round(3.0 / period_s)):
        plant.set_voltage(core.step(plant.time_s + offset, plant.read()).volts)
        plant.advance(period_s)
        lowest.append(ForbiddenSpace(arm).lowest_point_m(np.array(plant.state[:2])[None])[0])
    said = core.events.take()
    back = [e.message for e in said if e.kind == Kind.SENSORS_BACK]
    assert back and ('still on its plan' in back[-1] or 'planned again' in back[-1]), said
    assert Kind.GOAL_REACHED in [e.kind for e in said], said
    assert min(lowest) >= 0.0


def test_commands_lost_mid_move_then_the_arm_is_brought_back_not_dropped(arm, controller_config):
    """The motors get 0 V for 0.3 s mid-move while the controller runs on (its commands held
    up on the way: a DDS write blocks ~0.3 s when a node joins; the sim, as a motor
    controller does, applies 0 V after 0.1 s without one). The arm falls behind a plan at
    the motors' limits; it is brought back (braked from where it is, the goal planned again
    from there), not dropped by the tracking-error rule, and it never touches the floor."""
    core = plan_in_process(ArmController(arm, controller_config),
                           Planner(arm, config.load('planner')[1]))
    plant = ArmPlant(arm, START, seed=6)
    period_s = 1.0 / controller_config.loop_rate_hz
    core.submit_goal(plant.time_s, 1.1, 0.9)
    run(core, plant, 5.0, period_s, until=lambda: core.state == ArmState.HOLDING)
    run(core, plant, 1.0, period_s)
    core.submit_goal(plant.time_s, -0.6, 1.5)                  # up and over to the back
    run(core, plant, 2.0, period_s, until=lambda: core.state == ArmState.TRACKING)
    run(core, plant, 0.1, period_s)
    lowest = []
    for step in range(round(4.0 / period_s)):
        voltage = core.step(plant.time_s, plant.read()).volts
        plant.set_voltage(np.zeros(2) if step < round(0.3 / period_s) else voltage)
        plant.advance(period_s)
        lowest.append(ForbiddenSpace(arm).lowest_point_m(np.array(plant.state[:2])[None])[0])
    said = core.events.take()
    assert core.state != ArmState.ESTOPPED, said
    assert Kind.OFF_PLAN in [e.kind for e in said], said
    assert (Kind.GOAL_REACHED, (-0.6, 1.5)) in [(e.kind, e.goal_xy_m) for e in said], said
    assert min(lowest) >= 0.0


def test_a_move_whose_first_commands_are_held_up_waits_for_the_arm_and_keeps_off_the_floor(
        arm, controller_config):
    """The motors keep the hold's command over the first 40 ms of "low front → far low back"
    (up and over, to full reach 0.1 m above the floor): the shoulder, at its motors' limit,
    cannot make that up. Driven to catch up, the arm came to the plan's braking faster than
    the plan and went 0.39 m into the floor; the plan waits for it instead."""
    core = plan_in_process(ArmController(arm, controller_config),
                           Planner(arm, config.load('planner')[1]))
    plant = ArmPlant(arm, GoalValidator(arm).free_configurations(1.6, 0.1)[0], seed=0)
    period_s = 1.0 / controller_config.loop_rate_hz
    run(core, plant, 0.5, period_s)
    core.submit_goal(plant.time_s, -1.7, 0.1)
    lowest = []
    for step in range(round(3.0 / period_s)):
        voltage = core.step(plant.time_s, plant.read()).volts
        if step >= round(0.04 / period_s):
            plant.set_voltage(voltage)
        plant.advance(period_s)
        lowest.append(ForbiddenSpace(arm).lowest_point_m(np.array(plant.state[:2])[None])[0])
    said = core.events.take()
    assert (Kind.GOAL_REACHED, (-1.7, 0.1)) in [(e.kind, e.goal_xy_m) for e in said], said
    assert core.goals.latency.waiting_for_the_arm_s > 0.0       # the last goal's, that one
    assert min(lowest) >= 0.0
