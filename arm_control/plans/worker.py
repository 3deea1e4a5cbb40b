"""Answering a plan request in the worker: time it, and from rest answer twice.

A goal from rest is answered at once with a quick trajectory the arm starts on, then with
its refinement from a hand-over time a safe margin past when the refinement is expected to
be ready (``HandoverClock``) -- unless a newer request is already waiting -- and, when it
took so long that it surely came too late, once more from later on. ``send`` and ``newer``
are the worker's: pure of processes, so tests and benches call them directly.

``Worker`` and ``Keeper`` are the worker's and its keeper's logic: a typed message in
(``messages``), typed messages out, no pipes and no processes (``nodes/plan_worker.py``
carries them between processes).
"""

import threading
import time

import numpy as np

from arm_control.plans.cache import Serves
from arm_control.plans.goals import Goal
from arm_control.plans.messages import (Done, KeeperJob, KeeperResult, KeeperSettings,
                                        Keeping, KeepPath, Kept, PathPlan, PlanRequest,
                                        Ready, Settings, TimedPlan, TimePlan)
from arm_control.plans.timer import PlanTimer
from arm_control.realtime import raised
from arm_control.timing.moving_start import toppra_solver

# The refinement's hand-over comes this many times its expected time after the quick
# trajectory starts, and never sooner than this; its time is expected from the quick
# timing's, at the largest ratio seen lately, an older one weighing this much less with
# each goal (``HandoverClock``).
HANDOVER_SAFETY = 1.5
MIN_HANDOVER_S = 0.03
# ... and never later than this share of the quick trajectory (a later one gains little).
HANDOVER_SHARE = 0.4
# A refinement that came too late is tried once more from later on, up to this share.
RETRY_SHARE = 0.7
# At most this many paths wait for the keeper, the latest first.
KEEPER_QUEUE = 256
PROVE_TILES = 64            # forbidden-space cells proved per slice of the warm-up (ms each)
FIRST_RATIO = 12.0
RATIO_MEMORY = 0.7


class HandoverClock:
    """When a refinement can surely be ready: its time is expected as a multiple of the
    quick timing's (both grow with the path and with the machine's load), the multiple the
    largest seen lately."""

    def __init__(self):
        self.ratio = FIRST_RATIO

    def handover_s(self, quick_s: float, duration_s: float) -> float:
        """The hand-over for a quick timing that took ``quick_s`` and lasts ``duration_s``."""
        return min(max(MIN_HANDOVER_S, HANDOVER_SAFETY * self.ratio * quick_s),
                   HANDOVER_SHARE * duration_s)

    def seen(self, quick_s: float, refine_s: float) -> None:
        self.ratio = max(RATIO_MEMORY * self.ratio, refine_s / max(quick_s, 1e-4))


def answer(timer: PlanTimer, clock: HandoverClock, request: PlanRequest, plan, send,
           newer) -> bool:
    """Time ``plan`` for ``request`` and ``send`` the answer; from rest, the quick one, then
    (unless ``newer()``: another request waits) its refinement. True: a path from rest worth
    timing finely and keeping."""
    quick = timer.cache.serves(request, plan) is Serves.QUICK_THEN_FINE
    began = time.perf_counter()
    try:
        with raised(timer.config.planning_priority):     # the arm waits for this one
            timed = timer.time_plan(request, plan, quick=quick)
    except Exception as error:              # never leave a goal hanging
        timed = TimedPlan(request, None, f'timing the plan failed: {error!r}')
    send(timed)
    sent = time.perf_counter()
    quick_s = sent - began
    if not (quick and timed.ok):
        return False
    if newer():
        return True
    _refine(timer, clock, timed, sent, quick_s, send, newer)
    return True


def _refine(timer: PlanTimer, clock: HandoverClock, timed: TimedPlan, sent: float,
            quick_s: float, send, newer) -> None:
    """The quick answer's refinement, and once more from later on when it came too late."""
    duration_s = timed.trajectory.duration_s
    handover_s = clock.handover_s(quick_s, duration_s)
    for _ in range(2):
        began = time.perf_counter()
        try:
            # As the quick timing: a refinement that waits in the run queue misses its
            # hand-over, and the later one it is retried from ends later.
            with raised(timer.config.planning_priority):
                refined = timer.refine(timed, handover_s)
        except Exception:                   # the quick trajectory carries on
            refined = None
        done = time.perf_counter()
        clock.seen(quick_s, done - began)
        if refined is None:
            return
        send(refined)
        # The motion began no sooner than the quick answer went out: by then, surely late.
        # Once more from later on, which the controller takes if it had to drop this one.
        handover_s = done - sent + HANDOVER_SAFETY * (done - began)
        if done - sent < refined.handover_s or handover_s > RETRY_SHARE * duration_s \
                or newer():
            return


class WarmUp:
    """What the worker does while no request waits, a slice at a time: prove the
    forbidden-space cells the checks look up (``PROVE_TILES`` a slice: in all ~0.4 s of CPU
    the goals would otherwise pay for two to three times over), then answer a move between
    the first two presets and throw the answers away (numpy's and numba's first calls, the
    hand-over clock set), then start importing the moving-start solver (toppra, ~0.4 s)."""

    def __init__(self):
        self.stage = 0

    def step(self, timer: PlanTimer, clock: HandoverClock) -> bool:
        """One slice; False once all is done."""
        if self.stage == 0:
            self.stage += timer.ranking.prove_cells(PROVE_TILES)
        elif self.stage == 1:
            self.stage += 1
            _answer_between_presets(timer, clock)
        elif self.stage == 2:
            self.stage += 1             # in a thread of its own: a request need not wait
            threading.Thread(target=toppra_solver, daemon=True).start()
        return self.stage < 3


def _answer_between_presets(timer: PlanTimer, clock: HandoverClock) -> None:
    presets = timer.arm.presets
    if len(presets) < 2:
        return
    (_, x0, y0), (_, x1, y1) = presets[:2]
    starts = timer.ranking.validator.free_configurations(x0, y0)
    goals = timer.ranking.validator.free_configurations(x1, y1)
    if starts and goals:
        request = PlanRequest(0, Goal(x1, y1, 'warm-up'), starts[0], (0.0, 0.0), None, 0.0)
        answer(timer, clock, request, PathPlan(np.array([starts[0], goals[0]])),
               lambda timed: None, lambda: False)


class Worker:
    """The plan worker: ``take`` each message from the node (or the keeper's
    ``KeeperResult``) and answer through ``send`` -- ``TimedPlan``s, then ``Done`` per
    request, ``Kept`` counts, ``Ready`` once its first settings came. ``keeper`` (``send``,
    ``retune``, ``allow``) is handed the paths worth timing finely; ``newer()`` says whether
    another request waits (a refinement is then not worth making)."""

    def __init__(self, send, keeper):
        self.send, self.keeper = send, keeper
        self.timer = self.warm_up = None
        self.clock = HandoverClock()
        self.priority = 0               # the latest settings' planning_priority

    @property
    def warming(self) -> bool:
        return self.warm_up is not None

    def warm(self) -> None:
        """One slice of the warm-up (call only while no request waits)."""
        if not self.warm_up.step(self.timer, self.clock):
            self.warm_up = None

    def take(self, item, newer=lambda: False) -> None:
        match item:
            case Settings(arm, config) as settings:
                first = self.timer is None
                self.timer = PlanTimer(arm, config)
                self.priority = config.planning_priority
                self.keeper.retune(settings)
                self.send(Kept(0))
                if first:
                    self.send(Ready())
                    self.warm_up = WarmUp()
            case Keeping(allowed):
                self.keeper.allow(allowed)
            case KeepPath(request, plan):
                if not self.timer.cache.has(request, plan):
                    self.keeper.send(request, plan, pinned=True)
            case TimePlan(request, plan):
                if answer(self.timer, self.clock, request, plan, self.send, newer):
                    self.keeper.send(request, plan, pinned=False)
                self.send(Done(request.request_id))
            case KeeperResult(_, request, plan, trajectory, pinned):
                self.timer.cache.keep(request, plan, trajectory, pinned)
                self.send(Kept(len(self.timer.cache)))


class Keeper:
    """The keeper: ``take`` its settings and jobs; ``work`` times the latest job finely from
    rest with the latest settings (a job of older settings is dropped) and returns its
    ``KeeperResult``, or None."""

    def __init__(self):
        self.timer, self.generation, self.waiting = None, 0, []

    def take(self, item) -> None:
        match item:
            case KeeperSettings(generation, settings):
                self.generation, self.waiting = generation, []
                self.timer = PlanTimer(settings.arm, settings.config)
            case KeeperJob() as job:
                self.waiting = (self.waiting + [job])[-KEEPER_QUEUE:]

    def work(self) -> KeeperResult | None:
        job = self.waiting.pop()
        if job.generation != self.generation:
            return None
        try:
            trajectory = self.timer.fine_from_rest(job.request, job.plan)
        except Exception:                   # that path is timed afresh each time
            return None
        if trajectory is None:
            return None
        return KeeperResult(self.generation, job.request, job.plan, trajectory, job.pinned)
