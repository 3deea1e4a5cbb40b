"""The controller's core in closed loop with the simulated arm, in simulated time.

The arm (``ArmPlant``, sensor noise on) and the core run in-process: each control period
the core reads the sensors, returns a voltage, and the plant integrates it. The Kalman
filter is in the loop; nothing here reads the true state except the assertions.
"""

import dataclasses
import math

import numpy as np
import pytest

from arm_control import config
from arm_control.control.closed_loop import ClosedLoop
from arm_control.control.controller import ArmController
from arm_control.control.events import EventKind as Kind
from arm_control.control.goals import StraightLinePlanner
from arm_control.control.plans import PlanRequest
from arm_control.control.sensing import SensorReading
from arm_control.control.state_machine import ArmState, TRANSITIONS, Trigger
from arm_control.control.trajectory import time_optimal_trajectory, TrajectoryLimits
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.plant import ArmPlant
from arm_control.model.world import ForbiddenSpace
from arm_control.planning.planner import Planner

START = (1.5708, -1.5708)        # the sim's default: upper arm up, forearm level forward
DEG = math.pi / 180.0


@pytest.fixture(scope='module')
def controller_config():
    return config.load('controller')[1]


@pytest.fixture(scope='module')
def planner(arm):
    return Planner(arm, config.load('planner')[1])


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
    return np.abs(rig.true_q - rig.core.goals.goal_q)


# --- reaching goals, with the estimator in the loop -----------------------------------------

def test_reaches_every_preset_in_order_within_tolerance(arm, controller_config, planner):
    rig = Rig(arm, controller_config, planner, seed=3)
    names = [preset[0] for preset in arm.presets]
    for name in names:
        assert rig.core.submit_preset(rig.now, name, preempt=False)[0]
    assert rig.run(30.0, lambda: reached(rig.core) == len(names))
    assert len(rig.arrivals) == len(names)
    tolerance = controller_config.goal_tolerance_rad
    for goal_q, true_q, true_qd in rig.arrivals:
        assert np.all(np.abs(true_q - goal_q) < tolerance), np.degrees(true_q - goal_q)
        assert np.all(np.abs(true_qd) < 2 * controller_config.settled_velocity_rad_s)
    for (_, x, y) in arm.presets[-1:]:
        assert rig.kinematics.forward(rig.true_q) == pytest.approx((x, y), abs=0.02)
    assert rig.lowest_m == 0.0                          # no point of either link below y = 0
    assert np.max(np.abs(rig.voltages)) <= arm.battery.nominal_voltage
    arrivals = [e.message for e in rig.core.events.history if e.kind == Kind.GOAL_REACHED]
    assert len(arrivals) == len(names)
    assert all(f"'{name}'" in said for name, said in zip(names, arrivals))   # in order


def test_holds_the_goal_after_arriving(arm, controller_config, planner):
    rig = Rig(arm, controller_config, planner, seed=4)
    rig.core.submit_preset(rig.now, 'mid_score')
    assert rig.run(5.0, rig.in_state(ArmState.HOLDING))
    errors = []
    for _ in range(100):                                # 2 s at the goal
        rig.step()
        errors.append(np.max(goal_q_error(rig)))
    assert max(errors) < 0.5 * DEG
    assert rig.core.state == ArmState.HOLDING


def test_feedforward_alone_tracks_a_slow_trajectory(arm, controller_config):
    """No feedback at all: the coupled inverse dynamics and the motor model, evaluated at
    the setpoint, drive the simulated arm along a slow two-second move."""
    dynamics = ArmDynamics(arm)
    slow = TrajectoryLimits((0.6, 0.6), (1.0, 1.0), 11.0)
    trajectory = time_optimal_trajectory(np.array([(0.4, 0.3), (1.3, -0.9)]), dynamics,
                                         ForbiddenSpace(arm), slow)
    assert trajectory.duration_s > 1.5
    plant = ArmPlant(arm, (0.4, 0.3), seed=0)
    period_s = 0.02
    worst = 0.0
    for k in range(round(trajectory.duration_s / period_s) + 25):
        t = k * period_s
        plant.set_voltage(dynamics.voltage_for(*trajectory.sample(t + period_s / 2)))
        plant.advance(period_s)
        worst = max(worst, np.max(np.abs(plant.state[:2] - trajectory.sample(t + period_s)[0])))
    assert worst < 0.5 * DEG, f'{math.degrees(worst):.3f} deg'


def test_works_without_the_graph_planner_where_straight_lines_are_free(arm, controller_config):
    rig = Rig(arm, controller_config, StraightLinePlanner(arm), seed=5)
    rig.core.submit_goal(rig.now, -1.0, 1.0)
    assert rig.run(6.0, rig.in_state(ArmState.HOLDING))
    assert rig.lowest_m == 0.0


# --- the goal queue -------------------------------------------------------------------------

def test_the_queue_is_bounded_and_overflow_is_rejected(arm, controller_config, planner):
    rig = Rig(arm, controller_config, planner)
    size = controller_config.goal_queue_size
    results = [rig.core.submit_goal(rig.now, 1.0, 0.5 + 0.01 * i) for i in range(size + 5)]
    assert [ok for ok, _ in results] == [True] * size + [False] * 5
    rejected = [e for e in rig.core.events.history if e.kind == Kind.GOAL_REJECTED]
    assert [e.cause for e in rejected] == ['the queue full'] * 5
    waiting = rig.core.goals.queue.waiting
    assert [g.y_m for g in waiting] == pytest.approx([0.5 + 0.01 * i for i in range(size)])
    rig.run(0.1)
    assert rig.core.state == ArmState.TRACKING          # the queue still drives the arm


def test_a_flood_of_goals_is_answered_and_counted_and_memory_stays_bounded(
        arm, controller_config, planner):
    """5,000 goals at once: the queue takes its size, the rest are rejected -- said one by
    one up to the burst, then counted in one event a second. None goes unanswered."""
    rig = Rig(arm, controller_config, planner)
    rig.step()
    rig.core.events.take()
    for i in range(5000):
        rig.core.submit_goal(rig.now, 1.0, 0.5 + 1e-5 * i)
    rig.run(1.1)
    events = rig.core.events.take()
    queued = sum(e.kind == Kind.GOAL_QUEUED for e in events)
    said = sum(e.kind == Kind.GOAL_REJECTED for e in events)
    counted = sum(int(e.message.split()[0]) for e in events if e.kind == Kind.GOALS_REJECTED)
    assert queued == controller_config.goal_queue_size
    assert queued + said + counted == 5000
    assert said <= 25 and len(events) <= 200
    assert len(rig.core.events.history) <= 200


def test_goals_are_visited_in_order_with_a_dwell(arm, controller_config, planner):
    rig = Rig(arm, controller_config, planner)
    rig.core.submit_goal(rig.now, 0.9, 1.0, label='first')
    rig.core.submit_goal(rig.now, 1.0, 0.9, label='second')
    assert rig.run(5.0, rig.in_state(ArmState.HOLDING))
    arrived = rig.now
    assert rig.run(2.0, rig.in_state(ArmState.TRACKING))
    assert rig.now - arrived >= controller_config.dwell_s - rig.period_s
    assert rig.run(5.0, lambda: reached(rig.core) == 2)


# --- rejections ------------------------------------------------------------------------------

@pytest.mark.parametrize('goal, cause', [
    (dict(x=math.nan, y=1.0), 'not finite'),
    (dict(x=1.0, y=1.0, frame_id='world'), 'wrong frame'),
    (dict(x=1.0, y=1.0, z=0.5), 'off the plane'),
    (dict(x=5.0, y=1.0), 'out of reach'),
    (dict(x=1.0, y=-0.5), 'forbidden'),
    (dict(x=1.8, y=0.0), 'forbidden'),         # on the floor line: no clearance left
    (dict(x=1.2, y=0.0), 'forbidden'),
])
def test_a_rejected_goal_says_why_and_the_idle_arm_goes_to_error(arm, controller_config,
                                                                 planner, goal, cause):
    rig = Rig(arm, controller_config, planner)
    rig.run(0.2)
    held = rig.true_q
    ok, message = rig.core.submit_goal(rig.now, **goal)
    assert not ok
    assert rig.core.state == ArmState.ERROR
    (event,) = [e for e in rig.core.events.take() if e.kind == Kind.GOAL_REJECTED]
    assert event.cause == cause and event.level == 'warning'
    rig.run(1.0)
    assert np.max(np.abs(rig.true_q - held)) < 0.5 * DEG        # no motion
    assert rig.core.submit_goal(rig.now, 1.0, 1.0)[0]           # and it takes the next goal
    assert rig.run(5.0, rig.in_state(ArmState.HOLDING))


def test_a_rejected_goal_does_not_disturb_the_motion_or_the_queue(arm, controller_config,
                                                                  planner):
    rig = Rig(arm, controller_config, planner)
    rig.core.submit_preset(rig.now, 'back_score', preempt=False)
    rig.core.submit_preset(rig.now, 'stow', preempt=False)
    rig.run(0.2)
    assert rig.core.state == ArmState.TRACKING
    assert not rig.core.submit_goal(rig.now, math.inf, 0.0)[0]
    assert not rig.core.submit_preset(rig.now, 'nonsense')[0]
    assert rig.core.state == ArmState.TRACKING
    assert [g.label for g in rig.core.pending_goals()] == ["preset 'back_score'", "preset 'stow'"]


def test_unknown_preset_lists_the_known_ones(arm, controller_config):
    core = ArmController(arm, controller_config)
    ok, message = core.submit_preset(0.0, 'moon')
    assert not ok and all(name in message for name, _, _ in arm.presets)
    assert core.events.take()[-1].cause == 'no such preset'


def test_a_long_preset_name_is_quoted_only_in_part(arm, controller_config):
    """A 10 MB name must not be echoed: the event quotes a short prefix and the length."""
    core = ArmController(arm, controller_config)
    ok, message = core.submit_preset(0.0, 'x' * 10_000_000)
    assert not ok and len(message) < 300 and '10000000 characters' in message


# --- planning hand-off ---------------------------------------------------------------------

def test_asynchronous_planning_round_trip(arm, controller_config, planner):
    rig = Rig(arm, controller_config, planner=None)
    rig.step()
    rig.core.submit_preset(rig.now, 'high_score')
    rig.step()
    assert rig.core.state == ArmState.PLANNING
    (request,) = rig.core.take_plan_requests()
    assert rig.core.take_plan_requests() == []
    assert request.start_q == pytest.approx(START, abs=0.02)
    rig.run(0.3)                                         # the planner takes its time
    timed = rig.core.plan_timer.time_plan(request, planner.plan(request.start_q,
                                                                request.goal.xy))
    assert timed.ok and timed.compute_s < 1.0
    rig.core.on_timed_plan(rig.now, timed)
    assert rig.core.state == ArmState.TRACKING
    assert rig.run(5.0, rig.in_state(ArmState.HOLDING))


def test_no_plan_in_time_rejects_the_goal_without_moving(arm, controller_config):
    rig = Rig(arm, controller_config, planner=None)
    rig.run(0.2)
    held = rig.true_q
    rig.core.submit_preset(rig.now, 'back_score')
    assert rig.run(controller_config.planner_timeout_s + 0.2, rig.in_state(ArmState.ERROR))
    assert Kind.GOAL_FAILED in kinds(rig.core)
    rig.run(0.5)
    assert np.max(np.abs(rig.true_q - held)) < 0.5 * DEG


def test_the_planner_coming_and_going_is_said_once_each_and_named_in_a_failure(
        arm, controller_config):
    rig = Rig(arm, controller_config, planner=None)
    for available in (False, False, True, True, False, False):
        rig.core.on_planner_available(rig.now, available)
        rig.run(0.1)
    said = [kind for kind in kinds(rig.core) if kind.value.startswith('planner')]
    assert said == [Kind.PLANNER_WAITING, Kind.PLANNER_AVAILABLE, Kind.PLANNER_GONE]
    rig.core.submit_preset(rig.now, 'back_score')
    assert rig.run(controller_config.planner_timeout_s + 0.2, rig.in_state(ArmState.ERROR))
    (failure,) = [e for e in rig.core.events.history if e.kind == Kind.GOAL_FAILED]
    assert 'plan_path' in failure.message              # the missing service, by name


def test_a_late_answer_to_a_cancelled_request_is_ignored(arm, controller_config, planner):
    rig = Rig(arm, controller_config, planner=None)
    rig.step()
    rig.core.submit_preset(rig.now, 'back_score')
    rig.step()
    (request,) = rig.core.take_plan_requests()
    rig.core.cancel(rig.now)
    rig.core.on_timed_plan(rig.now, rig.core.plan_timer.time_plan(
        request, planner.plan(request.start_q, request.goal.xy)))
    assert rig.core.state == ArmState.WAITING


@pytest.mark.parametrize('waypoints', [
    [(1.5708, -1.5708), (0.2, -1.5708), (0.6, -0.8)],      # through forbidden space
    [(1.0, -1.0), (0.6, -0.8)],                             # not from where the arm is
    [(1.5708, -1.5708), (1.5, -1.4)],                       # not to the goal
])
def test_a_bad_plan_is_refused(arm, controller_config, waypoints):
    """A planner bug must not move the arm: the path is checked before it is followed."""
    rig = Rig(arm, controller_config, planner=None)
    rig.step()
    x, y = TwoLinkKinematics(1.0, 0.8).forward((0.6, -0.8))
    rig.core.submit_goal(rig.now, x, y)
    rig.step()
    (request,) = rig.core.take_plan_requests()
    bad = dataclasses.make_dataclass('P', ['ok', 'reason', 'waypoints_rad'])(
        True, '', np.array(waypoints))
    rig.core.on_timed_plan(rig.now, rig.core.plan_timer.time_plan(request, bad))
    assert rig.core.state == ArmState.ERROR and Kind.GOAL_FAILED in kinds(rig.core)
    rig.run(0.5)
    assert np.max(np.abs(rig.true_q - START)) < 0.5 * DEG      # it never moved


# --- preempting a moving arm ------------------------------------------------------------

def test_a_preempting_goal_takes_over_the_moving_arm_smoothly(arm, controller_config, planner):
    rig = Rig(arm, controller_config, planner, seed=6)
    rig.core.submit_preset(rig.now, 'back_score')
    rig.run(0.4)
    assert rig.core.state == ArmState.TRACKING
    moving = np.abs(rig.core.setpoint[1])
    assert np.max(moving) > 1.0                        # well under way
    rig.core.submit_preset(rig.now, 'floor_pickup')
    previous = rig.core.setpoint
    jumps, speed_jumps = [], []
    while rig.core.state != ArmState.HOLDING and rig.now < 10.0:
        rig.step()
        q, qd, qdd = rig.core.setpoint
        jumps.append(np.max(np.abs(q - previous[0] - previous[1] * rig.period_s)))
        speed_jumps.append(np.max(np.abs(qd - previous[1])))
        previous = rig.core.setpoint
    assert rig.core.state == ArmState.HOLDING
    assert rig.kinematics.forward(rig.true_q) == pytest.approx((1.2, 0.15), abs=0.03)
    # Position continues (within what one period of acceleration moves it) and so does
    # velocity (within one period of the acceleration limit).
    assert max(jumps) < 0.5 * max(controller_config.max_acceleration_rad_s2) * 0.02 ** 2 * 4
    assert max(speed_jumps) <= max(controller_config.max_acceleration_rad_s2) * 0.02 * 1.2
    assert rig.lowest_m == 0.0


def test_cancel_brakes_along_the_path_and_holds(arm, controller_config, planner):
    rig = Rig(arm, controller_config, planner, seed=7)
    rig.core.submit_preset(rig.now, 'back_score')
    rig.core.submit_preset(rig.now, 'stow', preempt=False)
    rig.run(0.4)
    assert np.max(np.abs(rig.core.setpoint[1])) > 1.0
    ok, _ = rig.core.cancel(rig.now)
    assert ok and kinds(rig.core)[-1] == Kind.CANCELLED
    assert rig.core.state == ArmState.WAITING and rig.core.pending_goals() == []
    rig.run(1.0)
    stopped = rig.true_q
    rig.run(1.0)
    assert np.max(np.abs(rig.true_q - stopped)) < 0.3 * DEG
    assert rig.core.state == ArmState.WAITING
    assert rig.lowest_m == 0.0


@pytest.mark.parametrize('start_xy, goal_xy', [((0.178, 0.199), (1.215, 0.085)),
                                               ((0.955, 0.157), (-0.351, 0.489)),
                                               ((-0.4, 0.3), (0.25, 0.45))])
def test_timed_moves_keep_the_clearance_from_forbidden_space(arm, controller_config, start_xy,
                                                             goal_xy):
    """Moves whose fastest shape, timed without the margin, grazes the floor: with it, the
    whole timed motion keeps ``world.clearance_rad`` from forbidden space."""
    margin = arm.world.clearance_rad
    padded = ForbiddenSpace(arm, margin)
    bare_arm = dataclasses.replace(arm, world=dataclasses.replace(arm.world, clearance_rad=0.0))
    planner_config = config.load('planner')[1]
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)

    def clear_throughout(world_arm):
        core = ArmController(world_arm, controller_config)
        world_planner = Planner(world_arm, planner_config)
        goal = core.goals.validator.check(*goal_xy).goal
        results = []
        for start in kinematics.inverse(*start_xy):
            if not padded.is_free(start):
                continue
            request = PlanRequest(1, goal, tuple(start), (0.0, 0.0), None, 0.0)
            timed = core.plan_timer.plan_and_time(request, world_planner)
            assert timed.ok, timed.reason
            trajectory = timed.trajectory
            times = np.linspace(0.0, trajectory.duration_s, 1000)
            results.append(bool(np.all(padded.is_free(
                np.array([trajectory.sample(t)[0] for t in times])))))
        return results

    assert all(clear_throughout(arm))
    assert not all(clear_throughout(bare_arm))


# --- safety ------------------------------------------------------------------------------

def reading_at(q, velocity=(0.0, 0.0)):
    return SensorReading(tuple(q), tuple(velocity), (math.nan, math.nan))


def drive(core, t, readings, period=0.02):
    """Step ``core`` with ``readings``; return the time after and the voltages."""
    voltages = []
    for reading in readings:
        voltages.append(core.step(t, reading))
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


def test_estop_when_the_tracking_error_stays_too_large(arm, controller_config):
    """The arm sags 25 deg away from its setpoint (slowly: a slipping gearbox, not a jump)
    and stays there: e-stop once the error has been above 20 deg for 0.5 s."""
    core = ArmController(arm, controller_config)
    t, _ = drive(core, 0.0, still(START, 10))
    limit = controller_config.tracking_error_limit_rad
    over_since, t_estop = None, None
    for reading in drift(START, -25 * DEG, 50) + still((START[0] - 25 * DEG, START[1]), 50):
        voltage = core.step(t, reading)
        if over_since is None and np.max(np.abs(core.tracking_error_rad)) > limit:
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
    assert np.any(core.step(t + 0.02, reading_at(START)) != 0.0)


def test_a_short_tracking_error_excursion_does_not_estop(arm, controller_config):
    core = ArmController(arm, controller_config)
    t, _ = drive(core, 0.0, still(START, 10))
    away = drift(START, -25 * DEG, 20)
    back = drift((START[0] - 25 * DEG, START[1]), 25 * DEG, 20)
    worst = 0.0
    for reading in away + back + still(START, 30):             # above 20 deg for < 0.5 s
        core.step(t, reading)
        worst = max(worst, np.max(np.abs(core.tracking_error_rad)))
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
    assert list(core.step(0.02, reading_at(q))) == [0.0, 0.0]
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
    assert rig.core.estop_holding
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
    states stop while the arm is held. Nothing then holds it: it falls."""
    holds = how != 'estop_holds_arm false'
    rig = estopped_mid_move(arm, controller_config, planner, estop_holds_arm=holds)
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
    assert not rig.core.estop_holding
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
    assert rig.core.estops == 0


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


# --- driver mode -----------------------------------------------------------------------------

def test_driver_mode_moves_the_tool_at_the_commanded_velocity(arm, controller_config):
    rig = Rig(arm, controller_config)
    rig.run(0.2)
    for _ in range(50):                                 # 1 s at 0.3 m/s forward
        rig.core.driver_command(rig.now, 0.3, 0.0)
        rig.step()
    q, qd, _ = rig.core.setpoint
    tool_velocity = rig.kinematics.jacobian(q) @ qd
    assert tool_velocity == pytest.approx((0.3, 0.0), abs=0.01)
    assert rig.core.state == ArmState.DRIVER


def test_driver_mode_stops_short_of_the_floor_and_holds(arm, controller_config):
    rig = Rig(arm, controller_config, start=(0.8, -1.2))
    rig.run(0.2)
    for _ in range(150):                                # 3 s of full stick straight down
        rig.core.driver_command(rig.now, 0.0, -5.0)
        rig.step()
    x, y = rig.kinematics.forward(rig.true_q)
    assert y > 0.0 and rig.true_q[0] > 0.0              # short of the floor ...
    assert y < 0.25                                     # ... but it did go down
    assert rig.lowest_m == 0.0
    assert rig.run(1.0, rig.in_state(ArmState.WAITING))  # commands stopped: hold
    here = rig.true_q
    rig.run(1.0)
    assert np.max(np.abs(rig.true_q - here)) < 0.3 * DEG


def test_driver_speed_is_limited(arm, controller_config):
    core = ArmController(arm, controller_config)
    core.step(0.0, reading_at(START))
    core.driver_command(0.0, 100.0, 0.0)
    assert np.hypot(*core.setpoints.driver.tool_velocity_mps) == pytest.approx(
        controller_config.driver_max_speed_mps)
    assert not core.driver_command(0.0, math.nan, 0.0)[0]


# --- every transition of the table, taken by the real controller -------------------------

def bring_to(state, arm, controller_config, planner):
    """A rig whose core is in ``state``."""
    asynchronous = state == ArmState.PLANNING
    rig = Rig(arm, controller_config, None if asynchronous else planner)
    if state == ArmState.NO_SENSORS:
        return rig
    rig.step()
    core = rig.core
    if state == ArmState.PLANNING:
        core.submit_preset(rig.now, 'high_score')
        rig.step()
    elif state == ArmState.TRACKING:
        core.submit_preset(rig.now, 'back_score')
        rig.step()
    elif state == ArmState.HOLDING:
        core.submit_goal(rig.now, 0.85, 1.0)
        rig.run(5.0, rig.in_state(ArmState.HOLDING))
    elif state == ArmState.ERROR:
        core.submit_goal(rig.now, math.nan, 0.0)
    elif state == ArmState.DRIVER:
        core.driver_command(rig.now, 0.1, 0.0)
        rig.step()
    elif state == ArmState.ESTOPPED:
        core.estop(rig.now)
    elif state == ArmState.DISABLED:
        core.enable(rig.now, False)
    assert core.state == state
    return rig


def take(trigger, rig, planner):
    """Do to the controller what should fire ``trigger`` in its current state."""
    core, state = rig.core, rig.core.state
    if trigger == Trigger.SENSORS_BACK:
        rig.step()
    elif trigger == Trigger.SENSORS_LOST:
        rig.sensors_on = False
        rig.run(0.3)
    elif trigger == Trigger.GOAL:
        if state in (ArmState.PLANNING, ArmState.TRACKING, ArmState.DRIVER):
            core.submit_preset(rig.now, 'mid_score')      # preempts (a queued goal waits)
        else:
            core.submit_goal(rig.now, 1.0, 1.0)
        rig.run(1.0, lambda: core.state != state)
    elif trigger == Trigger.PLAN_READY:
        (request,) = core.take_plan_requests()
        core.on_timed_plan(rig.now, core.plan_timer.time_plan(
            request, planner.plan(request.start_q, request.goal.xy)))
    elif trigger == Trigger.PLAN_FAILED:
        rig.run(2.0, rig.in_state(ArmState.ERROR))
    elif trigger == Trigger.ARRIVED:
        rig.run(6.0, rig.in_state(ArmState.HOLDING))
    elif trigger == Trigger.GOAL_FAILED:
        core.submit_goal(rig.now, 1.0, 1.0, frame_id='map')
    elif trigger == Trigger.CANCEL:
        core.cancel(rig.now)
    elif trigger == Trigger.ESTOP:
        core.estop(rig.now)
    elif trigger == Trigger.RESET:
        core.reset(rig.now)
    elif trigger == Trigger.DISABLE:
        core.enable(rig.now, False)
    elif trigger == Trigger.ENABLE:
        core.enable(rig.now, True)
    elif trigger == Trigger.DRIVER_COMMAND:
        core.driver_command(rig.now, 0.1, 0.0)
    elif trigger == Trigger.DRIVER_IDLE:
        rig.run(2.0, rig.in_state(ArmState.WAITING))
    elif trigger == Trigger.MOVED:
        rig.plant.reset((0.8, 0.9))                     # pushed, or the sim reset
        rig.step()


@pytest.mark.parametrize('state, trigger', sorted(TRANSITIONS, key=str))
def test_the_controller_takes_each_transition(arm, controller_config, planner, state, trigger):
    rig = bring_to(state, arm, controller_config, planner)
    take(trigger, rig, planner)
    assert (state, trigger, TRANSITIONS[(state, trigger)]) in rig.core.machine.history


def test_new_gains_act_from_the_next_period(arm, controller_config):
    """Run-time tuning: two cores see the same readings; one has its proportional gain
    doubled before the third period. Its feedback then differs by exactly kp·e."""
    kp, ki, kd = controller_config.shoulder_pid
    cores = [ArmController(arm, controller_config) for _ in range(2)]
    readings = [reading_at(START), reading_at((START[0] - 0.02, START[1]))] * 2
    for k, reading in enumerate(readings[:2]):
        for core in cores:
            core.step(0.02 * k, reading)
    cores[1].retune(arm, dataclasses.replace(controller_config, shoulder_pid=(2 * kp, ki, kd)))
    for core in cores:
        core.step(0.04, readings[2])
    error = cores[0].tracking_error_rad[0]
    assert abs(error) > 0.003
    difference = cores[1].feedback_v[0] - cores[0].feedback_v[0]
    assert difference == pytest.approx(kp * error, rel=1e-6)
