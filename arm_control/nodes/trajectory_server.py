"""The controller's ways in for ROS arm tools, named as ``joint_trajectory_controller`` names
them: the ``~/follow_joint_trajectory`` action (control_msgs/action/FollowJointTrajectory,
what MoveIt sends every plan through) and the ``~/joint_trajectory`` topic
(trajectory_msgs/JointTrajectory, fire and forget; an empty one stops and holds, as
``~/cancel``).

A shell: the checks are ``plans.trajectory_goals``, and a checked trajectory becomes the
core's current goal (``GoalRunner.follow``), followed by the control loop like a planned
one. A monitor timer (JTC's action_monitor_rate) sends feedback and ends the goal. Where
JTC refuses a goal outright (in ROS 2 that carries no result), this server accepts it and
aborts it at once with the code and the reason, so that a client learns why; a goal
preempted by a newer one is aborted with ``INVALID_GOAL`` (JTC: cancelled). Without
control_msgs the action is off, said once; the topic still works.
"""

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
import importlib
import math

import numpy as np
from rclpy.action import ActionServer, CancelResponse
from rclpy.task import Future
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from arm_control.config import JOINT_NAMES
from arm_control.control.motions import Motion
from arm_control.control.state_machine import STOPPED
from arm_control.nodes import messages
from arm_control.nodes.common import COMMANDS, guarded, listen, NodePart
from arm_control.plans.goals import Goal
from arm_control.plans.joint_trajectory import (ErrorCode, JointTolerance, TrajectoryPoint,
                                                TrajectoryRefused, TrajectoryRequest)
from arm_control.plans.trajectory_goals import FollowSettings, TrajectoryGoals, TrajectoryWatch
from arm_control.timing.bus import compile_kernels

try:
    from control_msgs.action import FollowJointTrajectory
except ImportError:                 # a machine without it: the topic only
    FollowJointTrajectory = None

MONITOR_RATE_HZ = 20.0          # feedback and verdicts this often (JTC's action_monitor_rate)
KERNELS_AFTER_S = 5.0           # the retiming's kernels loaded this long after the start
# A trajectory that starts from a moving setpoint takes over this far ahead (s), so that the
# checks finish before it begins.
MOVING_LEAD_S = 0.1


def seconds(duration) -> float:
    return duration.sec + 1e-9 * duration.nanosec


def request_from(trajectory, goal=None) -> TrajectoryRequest:
    """A JointTrajectory (and the action goal around it) as plain data."""
    points = tuple(TrajectoryPoint(tuple(p.positions), tuple(p.velocities),
                                   tuple(p.accelerations), seconds(p.time_from_start))
                   for p in trajectory.points)
    stamp = messages.stamp_s(trajectory.header)
    if goal is None:
        return TrajectoryRequest(tuple(trajectory.joint_names), points,
                                 0.0 if math.isnan(stamp) else stamp)

    def tolerances(given):
        return tuple(JointTolerance(t.name, t.position, t.velocity, t.acceleration)
                     for t in given)
    return TrajectoryRequest(tuple(trajectory.joint_names), points,
                             0.0 if math.isnan(stamp) else stamp,
                             tolerances(goal.path_tolerance), tolerances(goal.goal_tolerance),
                             seconds(goal.goal_time_tolerance))


def point(q, qd, qdd=None) -> JointTrajectoryPoint:
    return JointTrajectoryPoint(positions=[float(v) for v in q],
                                velocities=[float(v) for v in qd],
                                accelerations=[] if qdd is None else [float(v) for v in qdd])


@dataclass
class Active:
    """The action goal being followed."""

    handle: object
    goal: Goal
    watch: TrajectoryWatch
    future: Future
    note: str
    begun_s: float          # when it was handed to the core (what the core says since)


class TrajectoryServer(NodePart):
    """The action server and the topic, on the controller node (its core, lock, clock)."""

    def __init__(self, node, params):
        self.node = node
        self.settings = FollowSettings.from_parameters(params)
        self.config = node.config
        self.goals = TrajectoryGoals(node.arm, node.config, self.settings)
        self.count = 0
        self.active = None
        self.worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix='trajectories')
        # The retiming's kernels (and the spline), loaded in the thread that retimes once the
        # node's start is over (a trajectory before that loads them itself): loaded at start
        # they took the CPU and Python's lock from the node's start and its first goal.
        self.kernels_timer = node.create_timer(KERNELS_AFTER_S, self.load_kernels)
        listen(node, JointTrajectory, '~/joint_trajectory', self.on_topic, COMMANDS)
        self.server = None
        if FollowJointTrajectory is None:
            node.get_logger().warning(
                'control_msgs is not installed: ~/follow_joint_trajectory is off '
                '(~/joint_trajectory takes trajectories); see docs/ros_arm_interfaces.md')
            return
        self.server = ActionServer(node, FollowJointTrajectory, '~/follow_joint_trajectory',
                                   execute_callback=self.execute,
                                   cancel_callback=lambda request: CancelResponse.ACCEPT)
        # Only while a goal is followed: an idle timer would wake the executor 20 times a second.
        self.monitor_timer = node.create_timer(1.0 / MONITOR_RATE_HZ, self.monitor)
        self.monitor_timer.cancel()

    def load_kernels(self) -> None:
        """The retiming's kernels and the spline through points given without velocities,
        in the thread that uses them."""
        self.node.destroy_timer(self.kernels_timer)
        self.worker.submit(compile_kernels)
        self.worker.submit(importlib.import_module, 'scipy.interpolate')

    def command(self, call, *args):
        """``call(now, *args)`` on the core under the node's lock, from any thread (none of
        these cuts the power); what it said is published by the executor."""
        with self.node.lock:
            result = call(self.node.core_now_s(), *args)
        self.node.outputs.trigger()
        return result

    # ------------------------------------------------------------------ checks, hand-off

    def setpoint_at(self, t_s: float):
        """(q, q̇, q̈) the arm is commanded at ``t_s``; the estimate at rest before any."""
        core = self.node.core
        with self.node.lock:
            sample = core.setpoints.sample(t_s)
            if sample is not None:
                return tuple(np.array(v, float) for v in sample)
            q = core.estimate[:2].copy() if core.estimate is not None else np.zeros(2)
        return q, np.zeros(2), np.zeros(2)

    def in_worker(self, call, *args) -> Future:
        """``call(*args)`` on the checking thread, one at a time in the order asked: the
        executor keeps taking joint states meanwhile (a check that retimes takes tens of
        ms, and the loop stops the arm on readings a period late). The future's result:
        (True, value) or (False, the exception)."""
        future = Future()

        def run():
            try:
                future.set_result((True, call(*args)))
            except Exception as error:
                future.set_result((False, error))
        self.worker.submit(run)
        return future

    def check(self, request: TrajectoryRequest):
        """The checked trajectory from where the arm will be commanded when it can start:
        now at rest, ``MOVING_LEAD_S`` ahead when moving (``TrajectoryGoals.prepare``)."""
        node = self.node
        if self.config is not node.config:              # a run-time change of the reserves
            self.config = node.config
            self.goals = TrajectoryGoals(node.arm, node.config, self.settings)
        now = node.core_now_s()
        moving = bool(np.any(self.setpoint_at(now)[1]))
        prepared = self.goals.prepare(request, now + (MOVING_LEAD_S if moving else 0.0),
                                      self.setpoint_at)
        return prepared, moving

    def hand_off(self, checked, source: str):
        """The checked trajectory as the core's goal: (goal, watch, note), or
        ``TrajectoryRefused`` (``said``: the core has said why)."""
        node = self.node
        prepared, moving = checked
        self.count += 1
        final = node.core.kinematics.forward(prepared.final_q)
        goal = Goal(float(final[0]), float(final[1]), f'{source} {self.count}',
                    f' ({prepared.note})' if prepared.note else '', replan=False)
        with node.lock:
            now = node.core_now_s()
            begin = prepared.begin_s
            if now > begin:
                if moving:
                    raise TrajectoryRefused(ErrorCode.INVALID_GOAL, (
                        f'checked {now - begin:.3f} s too late to take over the moving arm '
                        'where it was checked from: send it again'))
                begin = now                           # from rest: it starts now
            motion = Motion(prepared.trajectory, begin)
        accepted, said = self.command(node.core.goals.follow, goal, motion)
        if not accepted:
            error = TrajectoryRefused(ErrorCode.INVALID_GOAL, said)
            error.said = True
            raise error
        return goal, TrajectoryWatch(motion, prepared.tolerances), prepared.note

    def refused(self, source: str, error: TrajectoryRefused) -> None:
        """Said as a rejected goal is (``~/events``, the error state when idle)."""
        if getattr(error, 'said', False):
            return
        self.command(self.node.core.reject,
                     f'{source} refused ({error.code.name}): {error.reason}',
                     error.code.name.lower())

    # ------------------------------------------------------------------ the topic

    @guarded
    def on_topic(self, msg: JointTrajectory) -> None:
        if not msg.points:                 # JTC: an empty trajectory stops and holds
            self.command(self.node.core.cancel)
            return
        request = request_from(msg)
        self.worker.submit(self.from_topic, request)

    def from_topic(self, request: TrajectoryRequest) -> None:
        """On the checking thread: checked, then followed (or refused, said)."""
        try:
            self.hand_off(self.check(request), 'joint_trajectory')
        except TrajectoryRefused as error:
            self.refused('joint_trajectory', error)
        except Exception as error:
            self.get_logger().error(f'joint_trajectory failed: {error!r}')

    # ------------------------------------------------------------------ the action

    async def execute(self, handle):
        result = FollowJointTrajectory.Result()
        try:
            request = request_from(handle.request.trajectory, handle.request)
            done, checked = await self.in_worker(self.check, request)
            if not done:
                raise checked
            goal, watch, note = self.hand_off(checked, 'follow_joint_trajectory goal')
        except TrajectoryRefused as error:
            self.refused('follow_joint_trajectory goal', error)
            handle.abort()
            result.error_code, result.error_string = int(error.code), error.reason
            return result
        except Exception as error:          # a bug must not leave the client waiting
            self.get_logger().error(f'follow_joint_trajectory goal failed: {error!r}')
            handle.abort()
            result.error_code = int(ErrorCode.INVALID_GOAL)
            result.error_string = f'internal error checking it: {error!r}'
            return result
        if self.active is not None:
            self.finish(self.active, ErrorCode.INVALID_GOAL, 'preempted by a newer goal')
        future = Future()
        self.active = Active(handle, goal, watch, future, note, self.node.core_now_s())
        self.monitor_timer.reset()
        return await future

    def finish(self, active: Active, code: ErrorCode, text: str, cancelled=False) -> None:
        """End the action goal with ``code`` (and what was done to it, when it succeeds)."""
        if cancelled:
            active.handle.canceled()
        elif code == ErrorCode.SUCCESSFUL:
            active.handle.succeed()
            text = active.note
        else:
            active.handle.abort()
        if self.active is active:
            self.active = None
        active.future.set_result(FollowJointTrajectory.Result(error_code=int(code),
                                                              error_string=text))

    @guarded
    def monitor(self) -> None:
        """Feedback, then the verdict: path and goal tolerances, cancel, or the arm no
        longer following it (then, as JTC, it brakes along its path and holds)."""
        active = self.active
        if active is None:
            self.monitor_timer.cancel()
            return
        core = self.node.core
        motion = active.watch.motion
        begun = active.begun_s
        with self.node.lock:
            now = self.node.core_now_s()
            following = (core.setpoints.timeline.last is motion and not core.setpoints.driving
                         and core.state not in STOPPED)
            said = [e for e in core.events.history if e.level != 'info' and e.time_s >= begun]
            why = str(said[-1]) if said else f'another goal or command took over ({core.state})'
            estimate = None if core.estimate is None else core.estimate.copy()
        if active.handle.is_cancel_requested:
            self.stop(motion)
            self.finish(active, ErrorCode.SUCCESSFUL, 'cancelled: braking to rest along its '
                                                      'path, holding there', cancelled=True)
            return
        if estimate is not None:
            self.feedback(active, now, estimate)
        verdict = active.watch.judge(now, following, why, estimate)
        if verdict is not None:
            code, text = verdict
            if code != ErrorCode.SUCCESSFUL:
                self.stop(motion)
                self.node.get_logger().warning(f'{active.goal.label} aborted ({code.name}): '
                                               f'{text}')
            self.finish(active, code, text)

    def stop(self, motion) -> None:
        """Brake along the trajectory and hold, if it is still the one the arm follows."""
        with self.node.lock:
            ours = self.node.core.setpoints.timeline.last is motion
        if ours:
            self.command(self.node.core.cancel)

    def feedback(self, active: Active, now: float, estimate) -> None:
        q, qd, qdd = active.watch.motion.sample(now)
        feedback = FollowJointTrajectory.Feedback(joint_names=list(JOINT_NAMES))
        feedback.header.stamp = self.node.get_clock().now().to_msg()
        feedback.desired = point(q, qd, qdd)
        feedback.actual = point(estimate[:2], estimate[2:])
        feedback.error = point(q - estimate[:2], qd - estimate[2:])
        active.handle.publish_feedback(feedback)
