"""The controller's core in closed loop with the simulated arm, in simulated time: goals
reached, the queue, rejections, the planning hand-off, preemption.

The arm (``ArmPlant``, sensor noise on) and the core run in-process: each control period
the core reads the sensors, returns a voltage, and the plant integrates it. The Kalman
filter is in the loop; nothing here reads the true state except the assertions.
"""

import dataclasses
import math

from controller_rig import DEG, goal_q_error, kinds, reached, reading_at, Rig, START
import numpy as np
import pytest

from arm_control import config
from arm_control.control.controller import ArmController, STILL_AFTER_S
from arm_control.control.events import EventKind as Kind
from arm_control.control.state_machine import ArmState
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.plant import ArmPlant
from arm_control.model.world import ForbiddenSpace
from arm_control.planning.planner import Planner
from arm_control.plans.goals import StraightLinePlanner
from arm_control.plans.messages import PlanRequest
from arm_control.plans.port import InProcessPlanning
from arm_control.timing import time_optimal_trajectory, TrajectoryLimits


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
    arrivals = [e.goal_xy_m for e in rig.core.events.history if e.kind == Kind.GOAL_REACHED]
    assert arrivals == [(x, y) for _, x, y in arm.presets]                  # in order


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


def test_only_an_arm_held_settled_with_nothing_to_do_holds_still(arm, controller_config,
                                                                 planner):
    """Holding still (the loop may tick at ``holding_rate_hz``): held, settled as at a goal
    for STILL_AFTER_S, no goal waiting; not on the way, nor once a goal or a push comes."""
    rig = Rig(arm, controller_config, planner, seed=4)
    rig.core.submit_preset(rig.now, 'mid_score')
    assert not rig.core.holding_still
    assert rig.run(1.0, rig.in_state(ArmState.TRACKING)) and not rig.core.holding_still
    assert rig.run(5.0, rig.in_state(ArmState.HOLDING))
    assert not rig.core.holding_still                   # the end of its settling
    assert rig.run(STILL_AFTER_S + 1.0, lambda: rig.core.holding_still)
    rig.plant.state[2] += 0.5                           # a push: 0.5 rad/s at the shoulder
    rig.step()
    assert rig.core.state == ArmState.HOLDING and not rig.core.holding_still
    assert rig.run(STILL_AFTER_S + 1.0, lambda: rig.core.holding_still)
    rig.core.submit_preset(rig.now, 'high_score')
    assert not rig.core.holding_still


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
    """5,000 goals at once at an idle arm: the first starts, the queue takes its size, the
    rest are rejected -- said one by one up to the burst, then counted in one event a
    second. None goes unanswered."""
    rig = Rig(arm, controller_config, planner)
    rig.step()
    rig.core.events.take()
    for i in range(5000):
        rig.core.submit_goal(rig.now, 1.0, 0.5 + 1e-5 * i)
    rig.run(1.1)
    events = rig.core.events.take()
    queued = sum(e.kind == Kind.GOAL_QUEUED for e in events)
    said = sum(e.kind == Kind.GOAL_REJECTED for e in events)
    counted = sum(e.count for e in events if e.kind == Kind.GOALS_REJECTED)
    assert queued == 1 + controller_config.goal_queue_size
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
    (request,) = rig.core.planning.take()
    assert rig.core.planning.take() == []
    assert request.start_q == pytest.approx(START, abs=0.02)
    rig.run(0.3)                                         # the planner takes its time
    timed = rig.core.plan_timer.time_plan(request, planner.plan(request.start_q,
                                                                request.goal.xy))
    assert timed.ok and timed.compute_s < 1.0
    rig.core.on_timed_plan(rig.now, timed)
    assert rig.core.state == ArmState.TRACKING
    assert rig.run(5.0, rig.in_state(ArmState.HOLDING))


def test_a_step_is_one_value_with_its_events_and_the_plan_requests_it_handed_on(
        arm, controller_config):
    """``step`` returns the volts with what they came from: the events said in that step
    (no other), the plan requests it handed to the core's planning (once); ``take_news``
    gives the events since the last take."""
    core = ArmController(arm, controller_config)
    first = core.step(0.0, reading_at(START))
    assert [e.kind for e in first.events] == [Kind.SENSORS_BACK] and not first.plan_requests
    assert np.all(first.volts == core.voltage) and first.estimate is not None
    core.submit_goal(0.01, 1.1, 0.9)
    planning = core.step(0.02, reading_at(START))
    assert planning.state == ArmState.PLANNING and planning.events == ()
    (request,) = planning.plan_requests
    assert planning.queue_version != first.queue_version
    assert core.planning.take() == [request]
    news = core.take_news()
    assert len(news.goals) == 1
    assert [e.kind for e in news.events] == [Kind.SENSORS_BACK, Kind.GOAL_QUEUED]
    assert core.step(0.04, reading_at(START)).plan_requests == ()
    steps = [core.step(0.02 * k, None) for k in range(3, 40)]
    lost = next(step for step in steps if step.events)
    assert [e.kind for e in lost.events] == [Kind.SENSORS_LOST]
    assert lost.unpowered and lost.state == ArmState.NO_SENSORS and not np.any(lost.volts)


def test_a_goal_for_an_idle_arm_is_asked_for_at_once_and_the_next_waits_its_turn(
        arm, controller_config):
    """Queued at an idle arm, a goal's plan is asked for when it comes (stamped then, handed
    on in the next step: in the node a goal ticks the loop at once); a goal queued behind
    it waits until the arm has reached the first."""
    rig = Rig(arm, controller_config, planner=None)
    rig.step()
    asked_s = rig.now
    rig.core.submit_goal(asked_s, 1.1, 0.9)
    assert rig.core.state == ArmState.PLANNING and rig.core.requests_waiting
    rig.step()                                  # handed on in the next step
    (request,) = rig.core.planning.take()
    assert request.goal.xy == pytest.approx((1.1, 0.9)) and request.sent_time_s == asked_s
    rig.core.submit_goal(rig.now, 0.9, 1.5)
    rig.step()
    assert rig.core.planning.take() == []
    assert [g.xy for g in rig.core.pending_goals()][-1] == pytest.approx((0.9, 1.5))


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


def test_a_goal_sent_before_the_planner_first_appears_waits_for_it_and_is_carried_out(
        arm, controller_config, planner):
    """At start-up the controller's client may find the planner seconds after the first goal:
    that goal is kept, said to wait once, and planned when the planner comes, not failed."""
    rig = Rig(arm, controller_config, planner)
    rig.core.on_planner_available(rig.now, False)
    rig.core.submit_preset(rig.now, 'mid_score')
    rig.run(controller_config.planner_timeout_s + 0.5)
    assert rig.core.state == ArmState.WAITING
    assert Kind.GOAL_FAILED not in kinds(rig.core)
    assert np.max(np.abs(rig.true_q - START)) < 0.5 * DEG       # nothing planned, no move
    rig.core.on_planner_available(rig.now, True)
    assert rig.run(10.0, lambda: reached(rig.core) == 1)
    assert kinds(rig.core).count(Kind.PLANNER_WAITING) == 1


def test_a_late_answer_to_a_cancelled_request_is_ignored(arm, controller_config, planner):
    rig = Rig(arm, controller_config, planner=None)
    rig.step()
    rig.core.submit_preset(rig.now, 'back_score')
    rig.step()
    (request,) = rig.core.planning.take()
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
    (request,) = rig.core.planning.take()
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
    moving = np.abs(rig.core.last_step.setpoint[1])
    assert np.max(moving) > 1.0                        # well under way
    rig.core.submit_preset(rig.now, 'floor_pickup')
    previous = rig.core.last_step.setpoint
    jumps, speed_jumps = [], []
    while rig.core.state != ArmState.HOLDING and rig.now < 10.0:
        rig.step()
        q, qd, qdd = rig.core.last_step.setpoint
        jumps.append(np.max(np.abs(q - previous[0] - previous[1] * rig.period_s)))
        speed_jumps.append(np.max(np.abs(qd - previous[1])))
        previous = rig.core.last_step.setpoint
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
    assert np.max(np.abs(rig.core.last_step.setpoint[1])) > 1.0
    ok, _ = rig.core.cancel(rig.now)
    assert ok and kinds(rig.core)[-1] == Kind.CANCELLED
    assert rig.core.state == ArmState.WAITING and rig.core.pending_goals() == []
    rig.run(1.0)
    stopped = rig.true_q
    rig.run(1.0)
    assert np.max(np.abs(rig.true_q - stopped)) < 0.3 * DEG
    assert rig.core.state == ArmState.WAITING
    assert rig.lowest_m == 0.0


def test_a_goal_sent_while_a_cancel_brakes_the_arm_is_reached(arm, controller_config, planner):
    """No trajectory may start from the braking arm (here it would need 0.07 V beyond the
    braking limit): the goal is then planned from where the arm comes to rest, not failed.
    Seen through ROS at the end of the flood test."""
    rig = Rig(arm, controller_config, planner, seed=7)
    rig.core.submit_preset(rig.now, 'back_score')
    rig.run(0.6)
    rig.core.cancel(rig.now)
    rig.step()
    rig.core.submit_preset(rig.now, 'floor_pickup')
    assert rig.run(4.0, lambda: rig.core.state == ArmState.HOLDING), kinds(rig.core)
    assert Kind.GOAL_FAILED not in kinds(rig.core)
    assert rig.kinematics.forward(rig.true_q) == pytest.approx((1.2, 0.15), abs=0.03)
    assert rig.lowest_m == 0.0


@pytest.mark.parametrize('start_xy, goal_xy', [((0.676, 0.148), (0.013, 0.589)),
                                               ((0.601, 0.24), (-0.036, 0.59)),
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
            answers = []
            InProcessPlanning(core, world_planner, answers.append).send([request])
            timed, = answers
            assert timed.ok, timed.reason
            trajectory = timed.trajectory
            times = np.linspace(0.0, trajectory.duration_s, 1000)
            results.append(bool(np.all(padded.is_free(
                np.array([trajectory.sample(t)[0] for t in times])))))
        return results

    assert all(clear_throughout(arm))
    assert not all(clear_throughout(bare_arm))
