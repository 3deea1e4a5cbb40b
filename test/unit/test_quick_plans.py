"""A goal starts on a quick trajectory and hands over to its refinement.

The quick one must be as sound as any (free at the world's check step, within every limit by
the exact electrical model, at rest at both ends) and close to the fine timing; the
refinement takes over with the same position and velocity and never makes the move slower;
the goal runner lets it take over only while that is still ahead and the motion it refines
is still the plan; through the worker the quick answer comes first, then the refinement.
"""

import math
import multiprocessing
import threading
import time

import numpy as np
from planning_checks import FRC_FILE
import pytest

from arm_control import config
from arm_control.control.closed_loop import ClosedLoop
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.world import ForbiddenSpace
from arm_control.nodes.plan_worker import _Incoming, PlanWorker
from arm_control.planning.poses import poses_from_waypoints, waypoints_from_poses
from arm_control.plans.cache import KeptTrajectories, preset_pairs, Serves
from arm_control.plans.goals import Goal
from arm_control.plans.messages import (Done, KeeperResult, Keeping, KeepPath, Kept, PathPlan,
                                        PlanRequest, Ready, Settings, TimedPlan, TimePlan)
from arm_control.plans.timer import BranchRanking, PlanTimer
from arm_control.plans.worker import Worker
from arm_control.timing import (bus, exact, refined_trajectory, time_optimal_trajectory,
                                TrajectoryLimits)
from arm_control.timing.bus import compile_kernels, exact_timing
from arm_control.timing.exact import fastest_speeds
from arm_control.timing.path import BlendedPath, FINE_GRID, grid_for
from arm_control.timing.rows import PathTerms, rows, speed_caps
from arm_control.timing.timing import check

STEP_RAD = 0.001745
PATHS = {
    'up to the front': [(1.5708, -1.5708), (0.3, 0.5)],
    'front over the top to the back': [(0.3, 0.5), (1.5708, 0.0), (2.8, -0.5)],
    'short hop': [(1.0, -1.0), (1.1, -0.9)],
    'floor to the far back': [(0.18, -0.05), (2.9, 0.15)],
}


@pytest.fixture(scope='module')
def setup():
    arm, controller = config.load('controller')
    return (arm, ArmDynamics(arm), ForbiddenSpace(arm),
            TrajectoryLimits.from_config(arm, controller))


def assert_sound(trajectory, start, end, dynamics, forbidden, limits):
    """At rest on ``start`` and ``end`` (or moving at the start of a refinement), free at the
    check step, within every limit by the exact model."""
    count = 5000
    while True:                                   # samples at least as dense as the step
        q, _, _ = trajectory.sample_many(np.linspace(0.0, trajectory.duration_s, count))
        if np.max(np.abs(np.diff(q, axis=0))) < STEP_RAD:
            break
        count *= 2
    assert np.all(forbidden.is_free(q))
    np.testing.assert_allclose(trajectory.sample(0.0)[0], start, atol=1e-9)
    final = trajectory.sample(trajectory.duration_s)
    np.testing.assert_allclose(final[0], end, atol=1e-9)
    np.testing.assert_allclose(final[1], 0.0, atol=1e-9)
    assert check(trajectory, dynamics, limits).passes


def test_one_path_timing_equals_the_timing_of_its_rows_at_any_sag(setup):
    """The bus iteration's fast solver (rows worked out once) gives the speeds the plain
    solver gives with the rows at that sag, from rest or moving, with a margin or not."""
    arm, dynamics, _, limits = setup
    path = BlendedPath(np.array(PATHS['front over the top to the back']), [0.4])
    grid = grid_for(path, FINE_GRID)
    terms = PathTerms.along(dynamics, path, grid)
    rng = np.random.default_rng(5)
    for margin, start_speed in ((0.0, 0.0), (0.4, 0.0), (0.0, 0.8)):
        solve = exact_timing(terms, grid, limits, margin, start_speed)
        for sag in (np.zeros(len(grid)), rng.uniform(0.0, 4.0, len(grid))):
            A, B, C, D, W = rows(terms, limits, sag, margin)
            plain = fastest_speeds(A[None], B[None], C[None], D[None], W,
                                   speed_caps(limits, terms.dq)[None], np.diff(grid),
                                   start_speed)[0]
            np.testing.assert_allclose(np.sqrt(solve(sag)), plain, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize('name', sorted(PATHS))
def test_the_quick_trajectory_is_sound_and_near_the_fine_timing(setup, name):
    arm, dynamics, forbidden, limits = setup
    waypoints = np.array(PATHS[name])
    quick = time_optimal_trajectory(waypoints, dynamics, forbidden, limits, quick=True)
    fine = time_optimal_trajectory(waypoints, dynamics, forbidden, limits, reshape=False)
    assert_sound(quick, waypoints[0], waypoints[-1], dynamics, forbidden, limits)
    assert quick.duration_s <= 1.03 * fine.duration_s


# Paths the planner gave on the FRC robot's world, around its shelf and over its bumper:
# many corners, each blended.
FRC_PATHS = {
    'over the top, six corners': [
        (1.238, -2.176), (2.173, -2.077), (2.679, -1.57), (2.766, -1.361), (2.766, -0.332),
        (2.609, -0.052), (1.932, 1.918)],
    'down the front, five corners': [
        (0.785, -0.919), (0.48, 0.523), (0.376, 0.925), (0.376, 1.483), (0.568, 1.675),
        (2.184, 2.3)],
    'around the back, nine corners': [
        (2.561, 1.253), (2.435, 1.117), (2.435, 0.523), (2.557, 0.07), (2.714, -0.262),
        (2.766, -0.332), (2.766, -1.361), (2.679, -1.57), (2.452, -1.797), (0.985, -1.803)],
}


@pytest.mark.parametrize('name', sorted(FRC_PATHS))
def test_along_many_corners_the_fine_timing_is_the_faster_and_the_quick_one_near_it(name):
    """On a finer grid the same path can only be timed as fast or faster (within the
    iteration's tolerance), and the quick timing, on few stages, stays near it: both had
    missed the blends' accelerations between their grid points (the fine one 1.45x the
    quick one, the quick one up to 3.8x the fine one)."""
    arm, controller = config.load('controller', str(FRC_FILE))
    dynamics, forbidden = ArmDynamics(arm), ForbiddenSpace(arm)
    limits = TrajectoryLimits.from_config(arm, controller)
    waypoints = np.array(FRC_PATHS[name])
    quick = time_optimal_trajectory(waypoints, dynamics, forbidden, limits, quick=True)
    fine = time_optimal_trajectory(waypoints, dynamics, forbidden, limits, reshape=False)
    assert_sound(quick, waypoints[0], waypoints[-1], dynamics, forbidden, limits)
    assert fine.duration_s <= 1.01 * quick.duration_s
    assert quick.duration_s <= 1.25 * fine.duration_s


# Floor pickup to full extension 0.10 m up on the default arm: the planner's straight joint
# line keeps the clearance, and so must any bend of it.
FLOOR_TO_FULL_EXTENSION = [(0.8418, -1.682), (0.2618, -0.4623)]


@pytest.mark.parametrize('name', ['floor to full extension, in the clearance']
                         + sorted(FRC_PATHS))
def test_a_bent_path_is_never_slower_than_the_path_itself(name):
    """The bend is taken only where it is faster: the search times shapes on few stages and
    had kept bends that took 2-4 % longer than the planner's path, in the clearance (where
    it sought room the clearance forbade) and around many corners; and a bend fixed in one
    spot must not be held back everywhere (5 % slower near the floor)."""
    if name in FRC_PATHS:
        arm, controller = config.load('controller', str(FRC_FILE))
        space, waypoints = ForbiddenSpace(arm), np.array(FRC_PATHS[name])
    else:
        arm, controller = config.load('controller')
        space = ForbiddenSpace(arm, arm.world.clearance_rad)
        waypoints = np.array(FLOOR_TO_FULL_EXTENSION)
    dynamics, limits = ArmDynamics(arm), TrajectoryLimits.from_config(arm, controller)
    unbent = time_optimal_trajectory(waypoints, dynamics, space, limits, reshape=False)
    bent = time_optimal_trajectory(waypoints, dynamics, space, limits)
    assert_sound(bent, waypoints[0], waypoints[-1], dynamics, space, limits)
    assert bent.duration_s <= 1.002 * unbent.duration_s


def test_no_timing_compiles_a_kernel_after_the_warm_up(setup):
    """The nodes compile the timing's kernels before they serve (``compile_kernels``); a
    goal's timing must then find them compiled for its arrays: a read-only sag had numba
    compile a second version of one, for a second or more, in the middle of a goal."""
    arm, dynamics, forbidden, limits = setup
    compile_kernels()
    kernels = (bus._judge, exact._fastest, exact._one_path, exact._passes_one_path)
    compiled = [len(kernel.signatures) for kernel in kernels]
    ranking = BranchRanking(arm)
    for waypoints in PATHS.values():
        waypoints = np.array(waypoints)
        quick = time_optimal_trajectory(waypoints, dynamics, forbidden, limits, quick=True)
        refined_trajectory(quick, 0.05, dynamics, forbidden, limits)
        time_optimal_trajectory(waypoints, dynamics, forbidden, limits)
        ranking.duration_s(waypoints)
    assert [len(kernel.signatures) for kernel in kernels] == compiled


@pytest.mark.parametrize('name', ['up to the front', 'front over the top to the back',
                                  'floor to the far back'])
def test_the_refinement_takes_over_seamlessly_and_never_slows_the_move(setup, name):
    arm, dynamics, forbidden, limits = setup
    waypoints = np.array(PATHS[name])
    quick = time_optimal_trajectory(waypoints, dynamics, forbidden, limits, quick=True)
    handover = 0.08
    refined = refined_trajectory(quick, handover, dynamics, forbidden, limits)
    assert refined is not None
    q, qd, _ = quick.sample(handover)
    np.testing.assert_allclose(refined.sample(0.0)[0], q, atol=1e-9)
    np.testing.assert_allclose(refined.sample(0.0)[1], qd, atol=1e-9)
    assert handover + refined.duration_s < quick.duration_s
    assert_sound(refined, q, waypoints[-1], dynamics, forbidden, limits)


def test_no_refinement_past_the_end_of_the_quick_trajectory(setup):
    arm, dynamics, forbidden, limits = setup
    waypoints = np.array(PATHS['short hop'])
    quick = time_optimal_trajectory(waypoints, dynamics, forbidden, limits, quick=True)
    assert refined_trajectory(quick, quick.duration_s, dynamics, forbidden, limits) is None
    assert refined_trajectory(quick, 2.0 * quick.duration_s, dynamics, forbidden,
                              limits) is None


# --- the goal runner -------------------------------------------------------------------------

def started_goal(arm, planner, preset='back_score'):
    """A closed loop whose core took a quick plan to ``preset``: (loop, quick, its motion)."""
    loop = ClosedLoop(arm, config.load('controller')[1])
    loop.step()
    loop.core.submit_preset(loop.now, preset)
    loop.step()
    (request,) = loop.core.planning.take()
    timer = loop.core.plan_timer
    plan = timer.ranking.plan(planner, request.start_q, request.goal.xy)
    quick = timer.time_plan(request, plan, quick=True)
    loop.core.on_timed_plan(loop.now, quick)
    return loop, quick, loop.core.setpoints.timeline.last


def test_a_refinement_in_time_takes_over_at_its_hand_over(arm, planner):
    loop, quick, motion = started_goal(arm, planner)
    handover = 0.1
    refined = loop.core.plan_timer.refine(quick, handover)
    assert refined is not None and refined.handover_s == handover
    loop.core.on_timed_plan(loop.now, refined)
    setpoints = loop.core.setpoints
    switch = motion.begin_s + handover
    for t in (switch - 0.05, switch - 1e-4):
        np.testing.assert_allclose(setpoints.sample(t)[0],
                                   quick.trajectory.sample(t - motion.begin_s)[0])
    for t in (switch, switch + 0.2):
        np.testing.assert_allclose(setpoints.sample(t)[0],
                                   refined.trajectory.sample(t - switch)[0])
    assert loop.core.goals.latency.trajectory_s == pytest.approx(
        handover + refined.trajectory.duration_s)
    assert loop.run(5.0, lambda: loop.core.goals.counts['reached'] == 1)
    assert loop.lowest_m == 0.0


def test_a_late_refinement_is_ignored_and_a_later_one_still_taken(arm, planner):
    loop, quick, motion = started_goal(arm, planner)
    refined = loop.core.plan_timer.refine(quick, 0.1)
    loop.core.on_timed_plan(motion.begin_s + 0.1, refined)
    later = motion.begin_s + 0.3
    np.testing.assert_allclose(loop.core.setpoints.sample(later)[0],
                               quick.trajectory.sample(later - motion.begin_s)[0])
    assert loop.core.goals.latency.refinement_too_late_by_s > 0.0
    retry = loop.core.plan_timer.refine(quick, 0.2)         # the worker's second try
    loop.core.on_timed_plan(motion.begin_s + 0.15, retry)
    np.testing.assert_allclose(loop.core.setpoints.sample(later)[0],
                               retry.trajectory.sample(later - motion.begin_s - 0.2)[0])


def test_a_refinement_of_a_motion_a_new_goal_took_over_from_is_ignored(arm, planner):
    loop, quick, motion = started_goal(arm, planner)
    refined = loop.core.plan_timer.refine(quick, 0.2)
    loop.run(0.04)
    loop.core.submit_preset(loop.now, 'stow')            # preempts: plans from the quick one
    loop.core.on_timed_plan(loop.now, refined)
    t = motion.begin_s + 0.25
    np.testing.assert_allclose(loop.core.setpoints.sample(t)[0],
                               quick.trajectory.sample(t - motion.begin_s)[0])


def test_a_goal_that_comes_again_along_the_same_path_takes_the_kept_fine_trajectory(arm,
                                                                                    planner):
    """Kept (``KeptTrajectories``), the fine timing from rest answers the same goal from the same
    start along the same path at once, sound, and sooner than the quick one; any other
    start is timed afresh."""
    controller = config.load('controller')[1]
    timer = PlanTimer(arm, controller)
    goal = timer.ranking.validator.check(-1.0, 1.0, 0.0, '', 'back').goal
    start = (1.5708, -1.5708)
    plan = timer.ranking.plan(planner, start, goal.xy)
    request = PlanRequest(1, goal, start, (0.0, 0.0), None, 0.0)
    quick = timer.time_plan(request, plan, quick=True)
    assert not quick.kept
    timer.cache.keep(request, plan, timer.fine_from_rest(request, plan))
    again = timer.time_plan(PlanRequest(2, goal, start, (0.0, 0.0), None, 5.0), plan, quick=True)
    assert again.kept and again.trajectory.duration_s < quick.trajectory.duration_s
    assert_sound(again.trajectory, start, plan.waypoints_rad[-1], timer.dynamics,
                 timer.forbidden, timer.limits)
    moved = (start[0] + 0.01, start[1])
    other = timer.ranking.plan(planner, moved, goal.xy)
    elsewhere = timer.time_plan(PlanRequest(3, goal, moved, (0.0, 0.0), None, 6.0), other,
                                quick=True)
    assert elsewhere.ok and not elsewhere.kept


def test_the_cache_says_which_mechanism_serves_a_request(arm, planner):
    """From rest along a path not kept: quick then refined; once kept: the kept one; a moving
    start, or no path: timed at once."""
    timer = PlanTimer(arm, config.load('controller')[1])
    goal = timer.ranking.validator.check(-1.0, 1.0, 0.0, '', 'back').goal
    start = (1.5708, -1.5708)
    plan = timer.ranking.plan(planner, start, goal.xy)
    request = PlanRequest(1, goal, start, (0.0, 0.0), None, 0.0)
    assert timer.cache.serves(request, plan) is Serves.QUICK_THEN_FINE
    moving = PlanRequest(2, goal, start, (0.5, 0.0), 1.0, 0.0)
    assert timer.cache.serves(moving, plan) is Serves.AT_ONCE
    assert timer.cache.serves(request, PathPlan(np.zeros((0, 2)), 'no path')) is Serves.AT_ONCE
    timer.cache.keep(request, plan, timer.fine_from_rest(request, plan))
    assert timer.cache.serves(request, plan) is Serves.KEPT and len(timer.cache) == 1


def test_the_worker_answers_typed_messages_without_a_process(arm, planner):
    """``Worker``: settings give ``Kept(0)`` and ``Ready``; a goal from rest a quick
    ``TimedPlan`` (then its refinement), ``Done``, and its path for the keeper; the keeper's
    result is kept (``Kept(1)``), and the same goal is then answered once, kept, and done."""
    sent, keeper = [], []

    class FakeKeeper:
        def retune(self, settings):
            pass

        def allow(self, working):
            pass

        def send(self, request, plan, pinned):
            keeper.append((request, plan, pinned))

    worker = Worker(sent.append, FakeKeeper())
    worker.take(Settings(arm, config.load('controller')[1]))
    assert sent == [Kept(0), Ready()] and worker.warming
    goal = worker.timer.ranking.validator.check(-1.0, 1.0, 0.0, '', 'back').goal
    start = (1.5708, -1.5708)
    plan = PathPlan(worker.timer.ranking.plan(planner, start, goal.xy).waypoints_rad)
    request = PlanRequest(1, goal, start, (0.0, 0.0), None, 0.0)
    sent.clear()
    worker.take(TimePlan(request, plan))
    answers = [m for m in sent if isinstance(m, TimedPlan)]
    assert answers[0].ok and not answers[0].kept and sent[-1] == Done(1)
    assert all(not math.isnan(m.handover_s) for m in answers[1:])
    assert keeper == [(request, plan, False)]
    sent.clear()
    worker.take(KeeperResult(0, request, plan, worker.timer.fine_from_rest(request, plan),
                             False))
    assert sent == [Kept(1)]
    sent.clear()
    worker.take(TimePlan(PlanRequest(2, goal, start, (0.0, 0.0), None, 1.0), plan))
    assert len(sent) == 2 and sent[0].kept and sent[1] == Done(2) and len(keeper) == 1


def test_a_goal_between_presets_finds_the_path_kept_for_it_after_the_round_trip(arm, planner):
    """The node has the paths between presets kept before they are asked for
    (``preset_pairs``). The arm then rests where its last motion ended, and the path comes
    back from the planner as tool poses: start and waypoints differ from the kept ones by
    rounding, and the kept trajectory is still found. From 0.001 rad away it is not."""
    controller = config.load('controller')[1]
    timer = PlanTimer(arm, controller)
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    presets = {name: (x, y) for name, x, y in arm.presets}

    def request(start_q, name):
        return PlanRequest(0, Goal(*presets[name], name), tuple(start_q), (0.0, 0.0), None,
                           0.0)

    def through_poses(start_q, name):               # the planner's path as PlanLink gets it
        plan = timer.ranking.plan(planner, start_q, presets[name])
        poses = poses_from_waypoints(kinematics, plan.waypoints_rad)
        return PathPlan(waypoints_from_poses(kinematics, poses, start_q, timer.forbidden))

    kept_starts = []
    for start_q, goal_xy in preset_pairs(timer.ranking.validator):
        if goal_xy == presets['back_score']:
            plan = through_poses(start_q, 'back_score')
            timer.cache.keep(request(start_q, 'back_score'), plan,
                             timer.fine_from_rest(request(start_q, 'back_score'), plan), True)
            kept_starts.append(np.asarray(start_q, float))
    mid = timer.ranking.validator.free_configurations(*presets['mid_score'])[0]
    to_stow = timer.time_plan(request(mid, 'stow'), through_poses(mid, 'stow'), quick=True)
    assert to_stow.ok and not to_stow.kept
    rest = to_stow.trajectory.sample(to_stow.trajectory.duration_s)[0]
    # Where the arm rests is a kept start only to within rounding (not the same floats).
    apart = min(np.max(np.abs(rest - start)) for start in kept_starts)
    assert 0.0 < apart <= 1e-6
    path = through_poses(rest, 'back_score')
    onward = timer.time_plan(request(rest, 'back_score'), path, quick=True)
    assert onward.ok and onward.kept
    assert_sound(onward.trajectory, rest, path.waypoints_rad[-1], timer.dynamics,
                 timer.forbidden, timer.limits)
    off = rest + np.array([0.001, 0.0])
    elsewhere = timer.time_plan(request(off, 'back_score'), through_poses(off, 'back_score'),
                                quick=True)
    assert elsewhere.ok and not elsewhere.kept


def test_trajectories_between_presets_stay_kept_however_many_other_goals_come(arm, planner):
    """The store keeps the last goals' trajectories up to its size, and those between presets
    for good: a robot sent to many points still finds its presets' moves kept."""
    controller = config.load('controller')[1]
    timer = PlanTimer(arm, controller)
    store = KeptTrajectories(size=2)
    start = (1.5708, -1.5708)

    def kept_for(x, y, pinned):
        goal = timer.ranking.validator.check(x, y, 0.0, '', 'goal').goal
        request = PlanRequest(0, goal, start, (0.0, 0.0), None, 0.0)
        plan = timer.ranking.plan(planner, start, goal.xy)
        store.add(request, plan, timer.fine_from_rest(request, plan), pinned)
        return request, plan
    preset = kept_for(-1.0, 1.0, pinned=True)
    others = [kept_for(x, 1.0, pinned=False) for x in (0.6, 0.8, 1.0)]
    assert len(store) == 3
    assert store.find(*preset) is not None
    assert store.find(*others[0]) is None                  # the oldest of the others went
    assert all(store.find(*other) is not None for other in others[1:])


def test_the_worker_sees_a_newer_goal_behind_a_path_for_the_keeper_only():
    """A goal's refinement is skipped only for a newer request to answer: a path between
    presets sent for the keeper meanwhile is not one, and nothing is lost by looking."""
    receiving, sending = multiprocessing.Pipe(duplex=False)
    incoming = _Incoming(receiving)
    sending.send(KeepPath('request', 'plan'))
    sending.send(Keeping(False))
    assert not incoming.newer()
    sending.send(TimePlan('request', 'plan'))
    assert incoming.newer()
    assert incoming.next() == KeepPath('request', 'plan')
    assert incoming.next() == Keeping(False)
    assert incoming.next() == TimePlan('request', 'plan')
    assert not incoming.waiting


# --- the worker -----------------------------------------------------------------------------

def wait_for(condition, event, timeout_s=10.0) -> bool:
    """Wait (on ``event``, set by each answer) until ``condition`` holds, or the timeout."""
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        event.wait(0.05)
        event.clear()
    return condition()


def test_the_worker_answers_a_goal_from_rest_at_once_then_refines_and_a_moving_start_once(
        arm, planner):
    """From rest: the quick trajectory at once, then a refinement, which ends sooner, and a
    second from a later hand-over only when the first surely came too late. (One is left out
    when, from the hand-over the worker's clock sets, it would not end sooner: on a loaded
    machine the hand-over comes late in the move.) A moving start: one answer. The keeper
    keeps the path from rest only once it may work."""
    controller = config.load('controller')[1]
    answers, arrived = [], threading.Event()

    def on_timed(timed):
        answers.append(timed)
        arrived.set()

    worker = PlanWorker(arm, controller, on_timed)
    try:
        assert worker.ready.wait(30.0)
        timer = PlanTimer(arm, controller)
        goal = timer.ranking.validator.check(-1.0, 1.0, 0.0, '', 'back').goal
        start = (1.5708, -1.5708)
        plan = timer.ranking.plan(planner, start, goal.xy)
        worker.allow_keeping(False)                 # as the node does while the arm moves
        worker.submit(PlanRequest(1, goal, start, (0.0, 0.0), None, 0.0), plan)
        assert wait_for(lambda: len(answers) >= 1, arrived, 30.0)
        quick = answers[0]
        assert quick.ok and math.isnan(quick.handover_s)
        wait_for(lambda: len(answers) >= 2, arrived)
        for refined in answers[1:]:
            assert refined.ok and refined.handover_s > 0.0
            assert refined.handover_s + refined.trajectory.duration_s \
                < quick.trajectory.duration_s
        assert len(answers) <= 3
        if len(answers) == 3:
            assert answers[2].handover_s > answers[1].handover_s
        before = len(answers)
        worker.submit(PlanRequest(2, goal, start, (0.3, 0.2), 10.0, 9.9), plan)
        assert wait_for(lambda: len(answers) > before, arrived, 30.0)
        assert not wait_for(lambda: len(answers) > before + 1, arrived, 1.0)   # nothing more
        moving = answers[before]
        assert moving.request.request_id == 2 and moving.ok and math.isnan(moving.handover_s)
        # Stopped, the keeper did nothing meanwhile; let work, it timed the path of the goal
        # from rest finely, and the worker kept it: the same goal again is answered with it,
        # and nothing more.
        time.sleep(1.0)
        assert worker.kept == 0
        worker.allow_keeping(True)
        deadline = time.monotonic() + 30.0
        while worker.kept < 1 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert worker.kept >= 1
        before = len(answers)
        worker.submit(PlanRequest(3, goal, start, (0.0, 0.0), None, 20.0), plan)
        assert wait_for(lambda: len(answers) > before, arrived, 30.0)
        assert not wait_for(lambda: len(answers) > before + 1, arrived, 1.0)
        kept = answers[before]
        assert kept.kept and kept.trajectory.duration_s < quick.trajectory.duration_s
    finally:
        worker.close()


# --- the branch choice ------------------------------------------------------------------------

@pytest.mark.parametrize('start_xy, goal_xy', [((0.25, 0.45), (-1.0, 1.0)),
                                               ((1.1, 0.9), (0.25, 0.45)),
                                               ((1.2, 0.15), (0.9, 1.5))])
def test_the_branch_chosen_is_the_one_the_fine_timing_finds_fastest(arm, planner, start_xy,
                                                                    goal_xy):
    """Chosen by time without timing finely: the elbow branch the planner answers with is the
    one whose fine timing from rest (bent where faster) takes the least time."""
    controller = config.load('controller')[1]
    timer = PlanTimer(arm, controller)
    validator = timer.ranking.validator
    start = validator.free_configurations(*start_xy)[-1]
    goal = validator.check(*goal_xy, 0.0, '', 'goal').goal
    chosen = timer.ranking.plan(planner, start, goal_xy)
    request = PlanRequest(1, goal, start, (0.0, 0.0), None, 0.0)
    durations = {}
    for q in validator.free_configurations(*goal_xy):
        fine = timer.time_plan(request, planner.plan_to_configuration(start, q))
        durations[q] = fine.trajectory.duration_s if fine.ok else math.inf
    assert len(durations) == 2
    fastest = min(durations, key=durations.get)
    np.testing.assert_allclose(chosen.waypoints_rad[-1], fastest, atol=1e-9)
