"""The controller's safety rules in closed loop with the simulated arm, in simulated time:
e-stops, joint limits, lost sensors, disable and enable, resets, the arm put elsewhere."""

import dataclasses
import math

from controller_rig import DEG, drift, drive, kinds, reached, reading_at, Rig, START, still
import numpy as np
import pytest

from arm_control.control.controller import ArmController
from arm_control.control.events import EventKind as Kind
from arm_control.control.state_machine import ArmState, Trigger


# --- safety ------------------------------------------------------------------------------

def test_estop_when_the_tracking_error_stays_too_large(arm, controller_config):
    """The arm sags 25 deg away from its setpoint (slowly: a slipping gearbox, not a jump)
    and stays there: e-stop once the error has been above 20 deg for 0.5 s."""
    core = ArmController(arm, controller_config)
    t, _ = drive(core, 0.0, still(START, 10))
    limit = controller_config.tracking_error_limit_rad
    over_since, t_estop = None, None
    for reading in drift(START, -25 * DEG, 50) + still((START[0] - 25 * DEG, START[1]), 50):
        voltage = core.step(t, reading).volts
        if over_since is None and np.max(np.abs(core.last_step.tracking_error_rad)) > limit:
            over_since = t
        if core.state == ArmState.ESTOPPED:
            t_estop = t
            break
        t += 0.02
    assert t_estop is not None and over_since is not None
    assert controller_config.tracking_error_time_s - 0.02 <= t_estop - over_since \
        <= controller_config.tracking_error_time_s + 0.04
    assert list(voltage) == [0.0, 0.0]
    assert kinds(core)[-1] == Kind.CONTROL_FAILED
    assert (ArmState.WAITING, Trigger.ESTOP, ArmState.ESTOPPED) in core.machine.history
    t, voltages = drive(core, t + 0.02, still(START, 5))        # 0 V until reset
    assert all(list(v) == [0.0, 0.0] for v in voltages)
    assert not core.submit_goal(t, 1.0, 1.0)[0]
    assert core.reset(t)[0] and core.state == ArmState.WAITING
    assert np.any(core.step(t + 0.02, reading_at(START)).volts != 0.0)


def test_a_short_tracking_error_excursion_does_not_estop(arm, controller_config):
    core = ArmController(arm, controller_config)
    t, _ = drive(core, 0.0, still(START, 10))
    away = drift(START, -25 * DEG, 20)
    back = drift((START[0] - 25 * DEG, START[1]), 25 * DEG, 20)
    worst = 0.0
    for reading in away + back + still(START, 30):             # above 20 deg for < 0.5 s
        core.step(t, reading)
        worst = max(worst, np.max(np.abs(core.last_step.tracking_error_rad)))
        t += 0.02
    assert worst > controller_config.tracking_error_limit_rad
    assert core.state == ArmState.WAITING


def test_a_dead_motor_mid_move_estops_the_arm(arm, controller_config, planner):
    """The shoulder's motors stop driving during a move: the arm falls behind its setpoint,
    and the controller cuts the power instead of pushing on."""
    rig = Rig(arm, controller_config, planner, seed=10)
    rig.core.submit_preset(rig.now, 'back_score')
    rig.run(0.3)
    apply = rig.plant.set_voltage
    rig.plant.set_voltage = lambda voltage: apply((0.0, voltage[1]))
    assert rig.run(3.0, rig.in_state(ArmState.ESTOPPED))
    assert kinds(rig.core)[-1] == Kind.CONTROL_FAILED
    assert list(rig.voltages[-1]) == [0.0, 0.0]


@pytest.mark.parametrize('joint, angle', [(0, -0.349 - 0.05), (1, 3.0 + 0.05)])
def test_estop_when_a_joint_is_past_its_limit(arm, controller_config, joint, angle):
    core = ArmController(arm, controller_config)
    core.step(0.0, reading_at(START))
    q = list(START)
    q[joint] = angle
    assert list(core.step(0.02, reading_at(q)).volts) == [0.0, 0.0]
    assert core.state == ArmState.ESTOPPED
    (failure,) = [e for e in core.events.history if e.kind == Kind.CONTROL_FAILED]
    assert (arm.shoulder, arm.elbow)[joint].name in failure.message     # the joint, named


def estopped_mid_move(arm, controller_config, planner, **changes):
    """A rig e-stopped by service 0.4 s into a fast move to back_score."""
    config = dataclasses.replace(controller_config, **changes)
    rig = Rig(arm, config, planner, seed=7)
    rig.core.submit_preset(rig.now, 'back_score')
    rig.core.submit_preset(rig.now, 'stow', preempt=False)
    rig.run(0.4)
    assert np.max(np.abs(rig.plant.state[2:])) > 1.0            # moving fast
    ok, _ = rig.core.estop(rig.now)
    assert ok and kinds(rig.core)[-1] == Kind.ESTOP
    assert rig.core.state == ArmState.ESTOPPED and rig.core.pending_goals() == []
    return rig


def test_an_estop_by_service_brakes_to_rest_and_holds_the_arm_there(arm, controller_config,
                                                                    planner):
    rig = estopped_mid_move(arm, controller_config, planner)
    assert not rig.core.unpowered                       # held, not at 0 V
    assert not rig.core.submit_preset(rig.now, 'stow')[0]
    rig.run(1.0)
    stopped = rig.true_q
    rig.run(2.0)
    assert np.max(np.abs(rig.true_q - stopped)) < 0.3 * DEG     # held up against gravity
    assert rig.core.state == ArmState.ESTOPPED and rig.lowest_m == 0.0
    ok, _ = rig.core.reset(rig.now)
    assert ok and kinds(rig.core)[-1] == Kind.RESET
    assert rig.core.state == ArmState.WAITING
    rig.run(1.0)
    assert np.max(np.abs(rig.true_q - stopped)) < 0.3 * DEG     # held where it was held
    assert rig.core.reset(rig.now) == (False, "nothing to reset in state 'waiting'")
    assert rig.core.submit_preset(rig.now, 'stow')[0]
    assert rig.run(6.0, lambda: reached(rig.core) == 1)


@pytest.mark.parametrize('how', ['estop_holds_arm false', 'e-stop again', 'sensors lost'])
def test_an_estop_cuts_the_power_when_asked_to_and_the_arm_falls(arm, controller_config,
                                                                 planner, how):
    """0 V: at once with ``estop_holds_arm`` false, on a second e-stop, or when the joint
    states stop while the arm is held sending plain volts (sending profiles, the robot plays
    the rest of the last one: test_lost_sensors.py). Nothing then holds it: it falls."""
    holds = how != 'estop_holds_arm false'
    mode = 'volts' if how == 'sensors lost' else controller_config.command_mode
    rig = estopped_mid_move(arm, controller_config, planner, estop_holds_arm=holds,
                            command_mode=mode)
    if holds:
        rig.run(1.0)
        if how == 'e-stop again':
            rig.core.estop(rig.now)
        else:
            rig.sensors_on = False
            lost_at = rig.now
            rig.run(1.0, lambda: not np.any(rig.voltages[-1]))
            assert rig.now - lost_at <= controller_config.joint_state_timeout_s + \
                2 * rig.period_s
    assert rig.core.unpowered
    rig.step()
    cut = rig.true_q
    rig.run(1.0)
    assert all(list(v) == [0.0, 0.0] for v in rig.voltages[-50:])
    assert np.max(np.abs(rig.true_q - cut)) > 5.0 * DEG
    assert rig.core.state == ArmState.ESTOPPED
    rig.sensors_on = True
    assert rig.core.estop(rig.now) == (True, 'already e-stopped: 0 V until reset')


def test_stops_commanding_when_joint_states_stop_and_recovers(arm, controller_config, planner):
    rig = Rig(arm, controller_config, planner, seed=8)
    rig.core.submit_preset(rig.now, 'high_score')
    rig.core.submit_preset(rig.now, 'stow', preempt=False)
    rig.run(0.3)
    rig.sensors_on = False
    lost_at = rig.now
    assert rig.run(1.0, rig.in_state(ArmState.NO_SENSORS))
    assert rig.now - lost_at <= controller_config.joint_state_timeout_s + 2 * rig.period_s
    assert list(rig.voltages[-1]) == [0.0, 0.0]
    assert Kind.SENSORS_LOST in kinds(rig.core)
    rig.run(0.3)
    assert all(list(v) == [0.0, 0.0] for v in rig.voltages[-10:])
    rig.sensors_on = True
    rig.step()
    assert rig.core.state in (ArmState.WAITING, ArmState.PLANNING, ArmState.TRACKING)
    # The interrupted goal and the queue come back: both are reached.
    assert rig.run(10.0, lambda: reached(rig.core) == 2)
    assert not rig.core.pending_goals()


def test_a_held_goal_is_held_again_when_the_joint_states_return(
        arm, controller_config, planner):
    """The goal reached, the joint states stop for a moment: 0 V, the arm sags. When they
    return it goes back to the goal, and holds it: the state says holding, not waiting."""
    rig = Rig(arm, controller_config, planner, seed=3)
    rig.core.submit_goal(rig.now, 0.85, 1.0)
    assert rig.run(5.0, rig.in_state(ArmState.HOLDING))
    rig.run(0.5)
    held = rig.true_q
    rig.sensors_on = False
    assert rig.run(1.0, rig.in_state(ArmState.NO_SENSORS))
    rig.run(0.05)
    assert np.max(np.abs(rig.true_q - held)) > 0.2 * DEG        # it sagged at 0 V
    rig.sensors_on = True
    rig.step()
    assert rig.core.state == ArmState.HOLDING
    rig.run(1.0)
    assert np.max(np.abs(rig.true_q - held)) < 0.5 * DEG
    assert rig.core.state == ArmState.HOLDING and rig.lowest_m == 0.0


def test_found_on_the_floor_line_the_arm_is_lifted_clear_before_it_is_held(
        arm, controller_config, planner):
    """The forearm's tip 1 cm above the floor (as after sagging at 0 V): the hold taken when
    the sensors arrive first lifts it clear by the margin, then holds it there."""
    shoulder = 0.3
    heading = math.asin((0.01 - math.sin(shoulder)) / arm.elbow.length_m)
    rig = Rig(arm, controller_config, planner, start=(shoulder, heading - shoulder))
    margin = arm.world.clearance_rad
    assert not rig.forbidden.clear_by(rig.true_q, margin)
    rig.run(1.0)
    lifted = rig.true_q
    assert Kind.SENSORS_BACK in kinds(rig.core)
    assert rig.forbidden.clear_by(lifted, 0.8 * margin)
    assert np.max(np.abs(lifted - (shoulder, heading - shoulder))) < 3.0 * margin
    rig.run(1.0)
    assert np.max(np.abs(rig.true_q - lifted)) < 0.3 * DEG
    assert rig.core.state == ArmState.WAITING and rig.lowest_m == 0.0


def test_disable_sends_zero_and_enable_takes_the_arm_back_to_where_it_was_held(
        arm, controller_config, planner):
    rig = Rig(arm, controller_config, planner)
    rig.run(0.5)
    held = rig.true_q
    assert rig.core.enable(rig.now, False)[0] and kinds(rig.core)[-1] == Kind.DISABLED
    assert list(rig.step()) == [0.0, 0.0]
    assert not rig.core.submit_goal(rig.now, 1.0, 1.0)[0]
    rig.run(0.3)                                       # it sags under gravity
    assert np.max(np.abs(rig.true_q - held)) > 1.0 * DEG
    rig.core.enable(rig.now, True)
    rig.run(1.5)
    assert np.max(np.abs(rig.true_q - held)) < 0.5 * DEG
    assert rig.core.state == ArmState.WAITING


def test_bursts_of_estops_and_resets_cannot_ratchet_the_arm_down(arm, controller_config,
                                                                 planner):
    """50 times: e-stop, e-stop again (0 V: it sags), reset -- quickly. Each reset takes the
    arm back to where it was held, so the sags do not add up."""
    rig = Rig(arm, controller_config, planner, seed=12)
    rig.core.submit_preset(rig.now, 'floor_pickup')
    assert rig.run(5.0, rig.in_state(ArmState.HOLDING))
    rig.run(1.0)
    held = rig.true_q
    for _ in range(50):
        rig.core.estop(rig.now)
        rig.step()
        rig.core.estop(rig.now)                        # 0 V
        rig.run(0.06)
        rig.core.reset(rig.now)
        rig.run(0.1)
    rig.run(2.0)
    assert np.max(np.abs(rig.true_q - held)) < 0.5 * DEG
    assert rig.lowest_m == 0.0


def test_a_sim_reset_mid_motion_holds_there_then_replans_the_goal(arm, controller_config,
                                                                  planner):
    rig = Rig(arm, controller_config, planner, seed=9)
    rig.core.submit_preset(rig.now, 'back_score')
    rig.run(0.4)
    rig.plant.reset(START)                              # the arm is somewhere else, at rest
    rig.step()
    assert (ArmState.TRACKING, Trigger.MOVED, ArmState.WAITING) in rig.core.machine.history
    assert Kind.ARM_MOVED in kinds(rig.core)
    assert rig.run(6.0, lambda: reached(rig.core) == 1)
    assert rig.kinematics.forward(rig.true_q) == pytest.approx((-1.0, 1.0), abs=0.03)
    assert ArmState.ESTOPPED not in [to for _, _, to in rig.core.machine.history]


def test_a_start_pushed_into_forbidden_space_gets_out_first(arm, controller_config, planner):
    """On its shoulder stop at -20 deg the upper arm is below the floor: the planner's
    first leg leads out, and from there the arm never goes below it again."""
    rig = Rig(arm, controller_config, planner, start=(-0.349, 0.5))
    assert not rig.forbidden.is_free(rig.true_q)
    rig.core.submit_preset(rig.now, 'mid_score')
    out_at = None
    while rig.core.state != ArmState.HOLDING and rig.now < 6.0:
        rig.step()
        if out_at is None and rig.forbidden.is_free(rig.true_q):
            out_at, rig.lowest_m = rig.now, 0.0
    assert rig.core.state == ArmState.HOLDING and out_at is not None
    assert rig.lowest_m == 0.0
