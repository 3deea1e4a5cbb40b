"""The controller's way to a plan: the ``plan_path`` client and the worker that times.

The core hands its requests to ``send`` in its step (the control loop's thread, under the
node's lock); they wait there for the executor, which calls the planner outside the lock:
its guard condition is made before the node's others, so in one wake the calls go out
before the events and the log lines of the same step. A request goes to the planner node as
GetPlan (start = the tool pose to plan from, goal = the point); its answer, turned back into
joint waypoints, goes to the worker process (``PlanWorker``) to be checked and timed; the
TimedPlan comes back through ``on_timed``, in the worker's result thread. A broken or empty
answer comes back at once, with the reason.

Once the arm has had no goal for a while, the paths between presets are asked for too, one
at a time, and handed to the worker's keeper alone (``keep_presets``): the first goal from a
preset to another then starts on its fine trajectory.
"""

from dataclasses import replace
import math
import threading
import time

from nav_msgs.srv import GetPlan

from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.world import ForbiddenSpace
from arm_control.nodes import messages
from arm_control.nodes.plan_worker import PlanWorker
from arm_control.planning.poses import waypoints_from_poses
from arm_control.plans.cache import preset_pairs
from arm_control.plans.goals import Goal, GoalValidator
from arm_control.plans.messages import PathPlan, PlanRequest, TimedPlan

# A call unanswered this long is sent again, at most RESENDS times; the earlier calls stay
# open and the first answer counts. An answer can be lost: a planner we have just found may
# not yet reach our reply reader (DDS discovery is not symmetric in time; under load it takes
# seconds). The planner answers a repeated request from its last answer, so a call sent
# again to a planner that is only slow costs a message (calls for older requests are
# forgotten when a newer one goes out, so they do not come in between).
RESEND_AFTER_S = 0.3
RESENDS = 2
# The paths between presets are asked for once the arm has had no goal for this long (s):
# not while the first goals come, when the planner and the worker have the most to do; one
# the planner did not answer is asked for again, this many calls in all.
PRESETS_AFTER_IDLE_S = 1.0
PRESET_CALLS = 3


class PlanLink:
    """One node's planner client and timing worker (the core's ``plans.port.Planning``:
    ``send``, answers to ``on_timed``; ``on_sent`` after calls went out); made first thing
    at the node's start, so that finding the planner and starting the worker go on while
    the rest is built."""

    def __init__(self, node, arm, config, on_timed, on_sent=lambda: None):
        self.node = node
        self.kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
        self.forbidden = ForbiddenSpace(arm)          # its joint limits, to unwrap angles
        self.planner_timeout_s = config.planner_timeout_s
        self.on_timed, self.on_sent = on_timed, on_sent
        self.outbox, self.outbox_lock = [], threading.Lock()   # handed on, not yet called
        self.sender = node.create_guard_condition(self._call_outbox)
        self.client = node.create_client(GetPlan, 'plan_path')
        self.worker = PlanWorker(arm, config, self._timed)
        self.calls = {}                      # unanswered call -> (sent at, request, sends)
        self.answered_s = {}                 # request id -> when the planner answered
        self.found = False                   # the client reaches the planner
        self.presets_to_keep = self._preset_requests(arm)     # (request, calls so far)
        self.preset_call = None              # the open call for one of them, and when
        self.idle_since_s = None             # no goal since (wall time)
        self.keeper_working = True

    def now_s(self) -> float:
        return self.node.get_clock().now().nanoseconds * 1e-9

    def ready(self) -> bool:
        """Goals can be planned: the client reaches the planner and the worker is up. Calls
        a restarted planner will never answer are forgotten after twice the timeout (wall
        time: planning takes it, whatever the clock)."""
        now = time.monotonic()
        self.found = self.client.service_is_ready()
        for future, (sent_s, request, sends) in list(self.calls.items()):
            if now - sent_s > 2.0 * self.planner_timeout_s:
                self._forget(future)
            elif self.found and now - sent_s > RESEND_AFTER_S \
                    and sends == self._sends(request) and sends <= RESENDS:
                self._call(request, sends + 1)
        return self.found and self.worker.ready.is_set()

    def settled(self) -> bool:
        """Nothing open with the planner and no path between presets left to ask for."""
        return not self.calls and self.preset_call is None and not self.presets_to_keep

    def busy(self) -> bool:
        """A plan is being made or timed (wall-time work): a call open, or the worker at it."""
        return bool(self.calls) or self.worker.busy

    def send(self, requests) -> None:
        """From any thread: ``requests`` to call for, in the executor."""
        with self.outbox_lock:
            self.outbox.extend(requests)
        self.sender.trigger()

    def _call_outbox(self) -> None:
        """Call for the requests handed on; the open calls for older ones are forgotten (the
        core takes the answer to its newest only), so none of them is sent again. The
        keeper stops: a goal to plan, not while it moves."""
        with self.outbox_lock:
            requests, self.outbox = self.outbox, []
        if not requests:
            return
        self.let_keeper_work(False)
        newest = {request.request_id for request in requests}
        for future, (_, request, _) in list(self.calls.items()):
            if request.request_id not in newest:
                self._forget(future)
        for request in requests:
            self._call(request, 1)
        self.on_sent()

    def let_keeper_work(self, working: bool) -> None:
        """Whether the worker's keeper may work now (said when it changes)."""
        if working != self.keeper_working:
            self.keeper_working = working
            self.worker.allow_keeping(working)

    def keep_presets(self, idle: bool) -> None:
        """When ``idle`` (no goal, nothing being planned) for a while and the planner is
        there, ask for the next path between presets; its answer goes to the keeper."""
        now = time.monotonic()
        idle = idle and self.found and self.worker.ready.is_set()     # since it could plan
        self.idle_since_s = (self.idle_since_s or now) if idle else None
        if self.preset_call is not None:
            future, sent_s, request, calls = self.preset_call
            if now - sent_s <= 2.0 * self.planner_timeout_s:
                return
            # Unanswered (a planner just found may not reach us yet, or gone meanwhile):
            # asked again later, at most PRESET_CALLS times in all.
            self.client.remove_pending_request(future)
            self.preset_call = None
            if calls < PRESET_CALLS:
                self.presets_to_keep.append((request, calls))
        if not (idle and now - self.idle_since_s >= PRESETS_AFTER_IDLE_S
                and self.presets_to_keep and self.worker.alive and not self.busy()):
            return
        request, calls = self.presets_to_keep.pop(0)
        future = self.client.call_async(self._message(request))
        self.preset_call = (future, now, request, calls + 1)
        future.add_done_callback(lambda done, r=request: self._preset_answered(r, done))

    def _preset_answered(self, request, future) -> None:
        if self.preset_call is None or self.preset_call[0] is not future:
            return                                          # given up on
        self.preset_call = None
        try:
            waypoints = waypoints_from_poses(self.kinematics,
                                             messages.poses_of(future.result().plan),
                                             request.start_q, self.forbidden)
        except Exception:                   # a broken answer: timed when asked
            return
        if len(waypoints) >= 2:             # none: the planner found no path
            self.worker.keep(request, PathPlan(waypoints))

    @staticmethod
    def _preset_requests(arm) -> list:
        """A request from rest for each move between presets (``preset_pairs``), not yet
        asked for."""
        names = {(x, y): name for name, x, y in arm.presets}
        return [(PlanRequest(0, Goal(*goal_xy, names[goal_xy]),
                             tuple(float(a) for a in start_q), (0.0, 0.0), None, 0.0), 0)
                for start_q, goal_xy in preset_pairs(GoalValidator(arm))]

    def _message(self, request) -> GetPlan.Request:
        header = messages.header(self.node.get_clock().now().to_msg())
        message = GetPlan.Request()
        message.start = messages.pose_stamped(*self.kinematics.tool_pose(request.start_q),
                                              header)
        message.goal = messages.pose_stamped(*request.goal.xy, 0.0, header)
        return message

    def _call(self, request, sends: int) -> None:
        future = self.client.call_async(self._message(request))
        self.calls[future] = (time.monotonic(), request, sends)
        future.add_done_callback(lambda done, r=request: self._answered(r, done))

    def _sends(self, request) -> int:
        """How many calls the open ones for ``request`` make: the latest one's count."""
        return max(sends for _, open_request, sends in self.calls.values()
                   if open_request.request_id == request.request_id)

    def _forget(self, future) -> None:
        self.client.remove_pending_request(future)
        del self.calls[future]

    def _timed(self, timed) -> None:
        """From the worker: stamped with when the planner answered and when it came back."""
        answered = self.answered_s.pop(timed.request.request_id, math.nan)
        self.on_timed(replace(timed, answered_s=answered, received_s=self.now_s()))

    def _answered(self, request, future) -> None:
        """The planner's path as joint waypoints, to the worker for timing."""
        if self.calls.pop(future, None) is None:
            return                                  # forgotten, or answered already
        for other in [f for f, call in self.calls.items()
                      if call[1].request_id == request.request_id]:
            self._forget(other)
        self.answered_s[request.request_id] = self.now_s()
        try:
            poses = messages.poses_of(future.result().plan)
        except Exception as error:                  # a broken answer must not stop the node
            return self._timed(TimedPlan(request, None, f'the planner call failed: '
                                                        f'{error!r}'))
        if not poses:
            return self._timed(TimedPlan(request, None, f'no plan to {request.goal.label}: '
                                                        'the planner found no path (its log '
                                                        'says why)'))
        try:
            waypoints = waypoints_from_poses(self.kinematics, poses, request.start_q,
                                             self.forbidden)
        except Exception as error:
            return self._timed(TimedPlan(request, None, f'the planner answered a path that '
                                                        f'is not of this arm: {error!r}'))
        try:
            self.worker.submit(request, PathPlan(waypoints))
        except (OSError, ValueError):               # the diagnostics say it is gone
            self._timed(TimedPlan(request, None, 'the plan worker process is gone'))

    def retune(self, arm, config) -> None:
        self.worker.retune(arm, config)
        self.presets_to_keep = self._preset_requests(arm)      # kept ones are gone

    def close(self) -> None:
        self.worker.close()
