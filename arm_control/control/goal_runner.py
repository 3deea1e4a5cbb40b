"""Goals from arrival to arrival: validated and queued, planned, taken over, reached or failed.

The runner shares the core's state machine, event log and setpoints (``controller.py``); it
decides which goal comes next and what a planner's answer means, the core runs the loop.
A goal waits in the queue; the next one starts when the arm is idle (after the dwell at the
last one); starting it asks for a plan from where the setpoint will be (``PlanHandoff``);
the plan's motion takes over on time, or the goal fails with the reason. A plan taken at
once from rest may be refined later (``PlanTimer.refine``): the refinement takes over from
its motion at the hand-over time when it comes before then, else the motion carries on.
"""

from dataclasses import dataclass, fields, replace
import math
from typing import Optional

import numpy as np

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.control.events import EventKind as Kind, EventLog
from arm_control.control.goal_queue import GoalQueue
from arm_control.control.motions import Motion, Setpoints, StoppingMotion, StraightStop
from arm_control.control.plan_handoff import PlanHandoff, Verdict
from arm_control.control.state_machine import ArmState as S, StateMachine, Trigger as T
from arm_control.plans.goals import Goal, GoalValidator
from arm_control.plans.messages import PlanRequest, TimedPlan
from arm_control.text import quote

# A preempting goal's new trajectory starts this far ahead on the current one: the time
# the planner and the timing need, so the switch happens on time. Doubled on each retry.
PREEMPT_LEAD_S = 0.1
# A refinement takes over only when it comes at least this long before its hand-over time.
HANDOVER_MARGIN_S = 0.002


@dataclass(frozen=True)
class GoalLatency:
    """Where the time went for the last goal taken, in seconds; NaN where a step did not
    happen (a goal from a kept trajectory is not timed; most are never refined)."""

    planner_round_trip_s: float = math.nan
    timing_s: float = math.nan              # the worker timing the path
    kept_trajectory_s: float = math.nan     # ... or taking a trajectory timed ahead
    handover_s: float = math.nan            # the answer's way back to the core
    waiting_to_start_s: float = math.nan    # until the current motion ends
    trajectory_s: float = math.nan          # the motion itself
    refinement_s: float = math.nan          # timing the refined rest of the motion
    refinement_too_late_by_s: float = math.nan
    waiting_for_the_arm_s: float = math.nan  # the motion held back for an arm behind it

    def items(self) -> list[tuple[str, float]]:
        """(what, seconds) of the steps that happened, for people."""
        return [(field.name.removesuffix('_s').replace('_', ' '), getattr(self, field.name))
                for field in fields(self) if math.isfinite(getattr(self, field.name))]


class GoalRunner:
    """The goal queue and the goal in hand."""

    def __init__(self, arm: ArmConfig, config: ControllerConfig, machine: StateMachine,
                 events: EventLog, setpoints: Setpoints):
        self.arm, self.config = arm, config
        self.machine, self.events, self.setpoints = machine, events, setpoints
        self.validator = GoalValidator(arm, config.clamp_unreachable_goals)
        self.queue = GoalQueue(config.goal_queue_size)
        self.plans = PlanHandoff(config.planner_timeout_s)
        self.goal_q: Optional[np.ndarray] = None     # where the current trajectory ends
        self.refinable = None                 # (request id, motion) a refinement may take over
        self.arrived_s = -math.inf
        self.last_error = ''
        self.counts = dict.fromkeys(('queued', 'started', 'rejected', 'reached', 'failed'), 0)
        self.planner_available: Optional[bool] = None    # as the node's client sees it
        self.planner_ever_seen = False
        self.latency = GoalLatency()                    # of the last goal taken

    # ------------------------------------------------------------------ goals in

    def submit(self, now_s: float, x: float, y: float, z: float, frame_id: str,
               label: Optional[str], preempt: bool, rest_q) -> tuple[bool, str]:
        """Queue a goal point -- or, with ``preempt``, drop the queue and go there now from
        wherever the arm is, moving or not. ``rest_q``: where the arm rests if it has no
        setpoint yet. Returns (accepted, the sentence said)."""
        state = self.machine.state
        if state in (S.ESTOPPED, S.DISABLED):
            fix = 'call reset' if state == S.ESTOPPED else 'enable it'
            return self.reject(now_s, f'goal {label or (x, y)} rejected: the arm is {state}; '
                                      f'{fix} first', str(state))
        check = self.validator.check(x, y, z, frame_id, label)
        if not check.ok:
            return self.reject(now_s, f'goal rejected: {check.reason}', check.category)
        goal, note = check.goal, f' ({check.goal.note})' if check.goal.note else ''
        if preempt:
            dropped = self.drop()
            extra = f'; {dropped} earlier goals dropped' if dropped else ''
            if self.machine.can(T.GOAL) and not self.waiting_for_planner:
                self.start(now_s, goal, rest_q)
                return self._accept(now_s, Kind.GOAL_ACCEPTED, goal,
                                    f'goal {goal.label} accepted{note}: going there now{extra}')
            self.queue.append(goal)
            return self._accept(now_s, Kind.GOAL_ACCEPTED, goal,
                                f'goal {goal.label} accepted{note}: next{extra}{self._wait()}')
        if self.queue.full:
            return self.reject(now_s, f'goal {goal.label} rejected: the queue is full '
                                      f'({self.config.goal_queue_size} goals waiting); the '
                                      'queued goals are kept', 'the queue full')
        self.queue.append(goal)
        self.counts['queued'] += 1
        said = self._accept(now_s, Kind.GOAL_QUEUED, goal, f'goal {goal.label} queued{note} '
                                                           f'({len(self.queue.waiting)} waiting)'
                                                           f'{self._wait()}')
        if self._ready_for_next(now_s):     # planned now, not half a period later on average
            self.start(now_s, self.queue.start_next(), rest_q, from_queue=True)
        return said

    def submit_preset(self, now_s: float, name: str, preempt: bool, rest_q) -> tuple[bool, str]:
        """A named goal from the parameter file, as a driver's button."""
        for preset, x, y in self.arm.presets:
            if preset == name:
                return self.submit(now_s, x, y, 0.0, '', f"preset '{name}'", preempt, rest_q)
        known = ', '.join(p[0] for p in self.arm.presets) or 'none'
        return self.reject(now_s, f'preset {quote(name)} rejected: no such preset (known: '
                                  f'{known})', 'no such preset')

    def reject(self, now_s: float, message: str, reason: str) -> tuple[bool, str]:
        """Say (or count, in a flood) why; an idle arm shows it in the ``error`` state."""
        self.counts['rejected'] += 1
        self.last_error = message
        self.events.reject(now_s, message, reason)
        if not self.queue and self.machine.can(T.GOAL_FAILED):
            self.machine.fire(T.GOAL_FAILED)
        return False, message

    def _accept(self, now_s: float, kind: Kind, goal, message: str) -> tuple[bool, str]:
        self.events.say(now_s, kind, 'info', message, goal_xy_m=goal.xy)
        return True, message

    # ------------------------------------------------------------------ the goal in hand

    def start(self, now_s: float, goal: Goal, rest_q, from_queue: bool = False) -> None:
        """Make ``goal`` current and ask for its plan (leaving driver mode by braking)."""
        if self.setpoints.driving:
            self.setpoints.brake(now_s)
        if not from_queue:
            self.queue.start(goal)
        self.plans.start(now_s)
        self.counts['started'] += 1
        self.machine.fire(T.GOAL)
        self.ask(now_s, goal, rest_q)

    def follow(self, now_s: float, goal: Goal, motion: Motion) -> tuple[bool, str]:
        """A trajectory given whole (a ROS client's, checked: ``trajectory_goals``) as the
        current goal, in place of the queue and any goal in hand: its motion takes over at
        its ``begin_s`` and is tracked, left and reached as a planned one's."""
        state = self.machine.state
        if not self.machine.can(T.GOAL) or state == S.DRIVER:
            # A driver's setpoint is extrapolated, not scheduled: the trajectory was checked
            # from a state the arm would not be in.
            why = 'a driver is in charge (call cancel first)' if state == S.DRIVER else \
                f'the arm is {state}'
            return self.reject(now_s, f'{goal.label} rejected: {why}', str(state))
        dropped = self.drop()
        self.queue.start(goal)
        self.plans.start(now_s)
        self.counts['started'] += 1
        self.machine.fire(T.GOAL)
        self.setpoints.schedule(motion)
        self.goal_q = motion.final_q
        self.machine.fire(T.PLAN_READY)
        self.latency = GoalLatency(trajectory_s=motion.end_s - motion.begin_s)
        return self._accept(now_s, Kind.GOAL_ACCEPTED, goal, f'{goal.label} accepted{goal.note}' +
                            (f'; {dropped} earlier goals dropped' if dropped else ''))

    def ask(self, now_s: float, goal: Goal, rest_q, lead_s: Optional[float] = None) -> None:
        """A plan from where the setpoint will be ``lead_s`` ahead (``PREEMPT_LEAD_S`` of
        wall time) if it is still moving then (the new motion takes over there), else from
        where it comes to rest. The motion the new one starts from is no longer refined: the
        new plan starts where it will be."""
        self.refinable = None
        if lead_s is None:
            lead_s = PREEMPT_LEAD_S
        start_time = now_s + lead_s
        timeline = self.setpoints.timeline
        if timeline.moving_at(start_time):
            q, qd, _ = timeline.sample(start_time)
            self.plans.ask(now_s, goal, q, qd, start_time, lead_s)
        else:
            last = timeline.last
            self.plans.ask(now_s, goal, rest_q if last is None else last.final_q, (0.0, 0.0),
                           None, lead_s)

    def take_requests(self) -> list[PlanRequest]:
        return self.plans.take()

    def on_timed_plan(self, now_s: float, timed: TimedPlan, rest_q) -> None:
        """Take a timed plan; answers to older requests are ignored, and so are refinements
        of a motion no longer in the plan or that come too late."""
        if math.isfinite(timed.handover_s):
            self._refine(now_s, timed)
            return
        last = self.setpoints.timeline.last
        answer = self.plans.answer(now_s, timed, -math.inf if last is None else last.end_s)
        if answer.verdict is Verdict.FAIL and timed.request.start_time_s is not None \
                and isinstance(last, (StraightStop, StoppingMotion)):
            # Braking to rest (cancelled, off its plan, back from a stall, out of driver
            # mode), or at rest since: none from the moving arm, so one from where it comes
            # to rest, so that a goal sent just after a cancel is not lost.
            self.ask(now_s, timed.request.goal, rest_q, max(last.end_s - now_s, 0.0) + 1e-6)
        elif answer.verdict is Verdict.FAIL:
            self.fail(now_s, answer.reason)
        elif answer.verdict is Verdict.RETRY:
            self.ask(now_s, timed.request.goal, rest_q, answer.lead_s)
        elif answer.verdict is Verdict.TAKE:
            motion = Motion(timed.trajectory, answer.begin_s)
            self.setpoints.schedule(motion)
            self.refinable = (timed.request.request_id, motion)
            self.goal_q = motion.final_q
            self.machine.fire(T.PLAN_READY)
            self.latency = self._latency(now_s, timed, answer.begin_s)

    def _refine(self, now_s: float, timed: TimedPlan) -> None:
        """The refinement takes over from its motion at the hand-over time, if that motion
        is still the last planned (no brake, preemption or next goal since) and the time is
        still ahead."""
        request_id, motion = self.refinable or (None, None)
        if (not timed.ok or timed.request.request_id != request_id or self.setpoints.driving
                or self.setpoints.timeline.last is not motion):
            return
        begin_s = motion.begin_s + timed.handover_s
        if now_s > begin_s - HANDOVER_MARGIN_S:     # too late: the quick trajectory carries on
            self.latency = replace(self.latency, refinement_too_late_by_s=now_s - (
                begin_s - HANDOVER_MARGIN_S))
            return
        refined = Motion(timed.trajectory, begin_s)
        self.setpoints.schedule(refined)
        self.refinable = None
        self.goal_q = refined.final_q
        self.latency = replace(self.latency, refinement_s=timed.compute_s,
                               trajectory_s=timed.handover_s + timed.trajectory.duration_s)

    def _latency(self, now_s: float, timed: TimedPlan, begin_s: float) -> GoalLatency:
        """Where the time went between asking for the plan and the motion's start."""
        asked = timed.request.sent_time_s
        answered = timed.answered_s if math.isfinite(timed.answered_s) else asked
        received = timed.received_s if math.isfinite(timed.received_s) else now_s
        return GoalLatency(
            planner_round_trip_s=answered - asked,
            **{'kept_trajectory_s' if timed.kept else 'timing_s': timed.compute_s},
            handover_s=max(received - answered - timed.compute_s, 0.0),
            waiting_to_start_s=begin_s - received, trajectory_s=timed.trajectory.duration_s)

    def fail(self, now_s: float, reason: str) -> None:
        self.plans.drop()
        self.refinable = None
        self.counts['failed'] += 1
        goal = self.queue.finish()
        self.setpoints.brake(now_s)
        if self.machine.can(T.PLAN_FAILED):
            self.machine.fire(T.PLAN_FAILED)
        self.last_error = f'goal {goal.label if goal else ""} failed: {reason}'
        self.events.say(now_s, Kind.GOAL_FAILED, 'warning', self.last_error,
                        goal_xy_m=goal.xy if goal else None)

    def planner_seen(self, now_s: float, available: bool) -> None:
        """Say when the planner comes or goes: a goal sent before it first comes waits for it
        in the queue; one sent while it is away later fails at its planner timeout, and the
        reason should already be on record."""
        if available == self.planner_available:
            return
        if available:
            self.planner_ever_seen = True
            self.events.say(now_s, Kind.PLANNER_AVAILABLE, 'info',
                            'the planner (plan_path) is available')
        elif self.planner_available is None:
            self.events.say(now_s, Kind.PLANNER_WAITING, 'info',
                            'waiting for the planner (plan_path) to appear')
        else:
            self.events.say(now_s, Kind.PLANNER_GONE, 'warning',
                            'the planner (plan_path) is gone: goals fail until it is back')
        self.planner_available = available

    def supervise(self, now_s: float, estimate) -> None:
        """The planner's deadline, arrival, and the next goal once the arm is idle."""
        if self.plans.overdue(now_s):
            note = ' (the plan_path service is not available)' \
                if self.planner_available is False else ''
            self.fail(now_s, f'the planner did not answer within '
                             f'{self.config.planner_timeout_s:g} s{note}')
        state = self.machine.state
        if state == S.TRACKING and self._arrived(now_s, estimate):
            self._arrive(now_s, estimate)
        if self._ready_for_next(now_s):
            self.start(now_s, self.queue.start_next(), estimate[:2], from_queue=True)

    @property
    def waiting_for_planner(self) -> bool:
        """At start-up, until the node's client has found the planner: goals are kept in the
        queue, not planned (they would fail at the planner timeout). A planner that was there
        and is gone is different: its goals fail, with the reason, until it is back."""
        return self.planner_available is False and not self.planner_ever_seen

    def _wait(self) -> str:
        return '; planned once the planner is up' if self.waiting_for_planner else ''

    def _ready_for_next(self, now_s: float) -> bool:
        """A goal waits and the arm is idle: waiting, after an error, or held past the dwell."""
        state = self.machine.state
        return bool(self.queue.waiting) and not self.waiting_for_planner and (
            state in (S.WAITING, S.ERROR) or (
                state == S.HOLDING and now_s >= self.arrived_s + self.config.dwell_s))

    def _arrived(self, now_s: float, estimate) -> bool:
        """Done moving, both joints within tolerance of the goal and nearly still."""
        if self.setpoints.moving_at(now_s) or self.goal_q is None:
            return False
        return bool(np.all(np.abs(estimate[:2] - self.goal_q) <= self.config.goal_tolerance_rad)
                    and np.all(np.abs(estimate[2:]) <= self.config.settled_velocity_rad_s))

    def _arrive(self, now_s: float, estimate) -> None:
        error = np.degrees(estimate[:2] - self.goal_q)
        self.machine.fire(T.ARRIVED)
        self.arrived_s = now_s
        self.counts['reached'] += 1
        goal = self.queue.finish()
        went = ', '.join(f'{name} {1000 * seconds:.1f} ms' for name, seconds in
                         self.latency.items())
        self.events.say(now_s, Kind.GOAL_REACHED, 'info',
                        f'reached {goal.label} {now_s - self.plans.started_s:.2f} s after '
                        f'starting it (error {error[0]:+.2f}, {error[1]:+.2f} deg; {went})',
                        goal_xy_m=goal.xy)

    def interrupt(self) -> None:
        """The arm stopped under the goal (sensors lost, moved): it goes first again."""
        self.plans.drop()
        self.refinable = None
        self.queue.put_back()
        self.goal_q = None

    def drop(self) -> int:
        """Forget every goal; returns how many there were."""
        self.plans.drop()
        self.refinable = None
        return self.queue.clear()
