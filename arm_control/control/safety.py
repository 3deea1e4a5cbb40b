"""The rules that stop the arm, and where it holds when control resumes.

E-stop at 0 V when control itself has failed: the tracking error stays above
``tracking_error_limit_rad`` for ``tracking_error_time_s`` (a dead motor, an arm that cannot
follow), or a joint reads past its hard stop by more than noise allows.

Resuming after a period at 0 V (an e-stop, a disable, lost sensors), the arm has sagged. When
the sensors alone stalled mid-motion and the arm still moves (a paused simulator froze
both), it brakes to rest from where it is, in a straight line, while its goal is planned
again from there; where that line is not free and the arm is near its plan, the plan goes
on from where the arm is on it. Otherwise the arm goes back to where it was last commanded
when that is near and the way there is free, so that bursts of cuts cannot ratchet it down;
otherwise it holds where it is -- braked there first if it moves -- lifted clear by the
shortest straight move first if it sagged within ``world.clearance_rad`` of forbidden
space. Each move is within what the motors surely give: no timing solve.
"""

import math
from typing import Optional

import numpy as np

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.control.motions import HoldTrajectory, Motion, StraightMove, StraightStop
from arm_control.model.world import ForbiddenSpace
from arm_control.timing import sure_acceleration_rad_s2, TrajectoryLimits

# A joint past its limit by more than this (or 6 potentiometer sigmas) e-stops the arm.
JOINT_LIMIT_MARGIN_RAD = 0.01
# Back to where it was last commanded from at most this far (a sag, not a fall).
RETURN_REACH_RAD = 0.15
# Still on its plan: within this of a point of it, and of its velocity there. (Through ROS, a
# paused sim leaves the arm 2-4 deg and 1-1.2 rad/s off it: the sim catches up 0.1 s, then
# applies the 0 V sent meanwhile until the controller's next command.)
REJOIN_RAD, REJOIN_RAD_S = math.radians(5.0), 1.5
# Moving, not at rest with noise: faster than this on either joint (rad/s).
MOVING_RAD_S = 0.3
# Off the motion to a goal by this share of ``tracking_error_limit_rad``, the arm leaves it:
# braked from where it is, the goal planned again; at most LEAVES_UNTIL_REACHED times before
# a goal is reached.
OFF_PLAN_SHARE = 0.5
LEAVES_UNTIL_REACHED = 3
# A stop from speed takes this many times what the sure accelerations need (as braking
# along a path does: ``StoppingMotion``).
STOP_MARGIN = 1.5
# A hold is lifted clear of forbidden space only from this near it: deeper in, the way out
# is the planner's.
LIFT_REACH_RAD = 0.35


class SafetyRules:
    """The e-stop rules of failed control, and the hold taken when control resumes."""

    def __init__(self, arm: ArmConfig, config: ControllerConfig, forbidden: ForbiddenSpace,
                 max_acceleration_rad_s2, max_velocity_rad_s):
        self.arm, self.config, self.forbidden = arm, config, forbidden
        self.max_acceleration = np.asarray(max_acceleration_rad_s2, float)
        self.max_velocity = np.asarray(max_velocity_rad_s, float)
        self.limit_margin_rad = np.array([max(JOINT_LIMIT_MARGIN_RAD,
                                              6.0 * j.potentiometer_noise_rad)
                                          for j in arm.joints])
        self.over_limit_since_s: Optional[float] = None

    def past_a_limit(self, potentiometer_rad) -> Optional[str]:
        """Why a joint reads past its hard stop (beyond noise), or None."""
        for index, joint in enumerate(self.arm.joints):
            margin = self.limit_margin_rad[index]
            angle = potentiometer_rad[index]
            if not joint.min_angle_rad - margin <= angle <= joint.max_angle_rad + margin:
                return (f'{joint.name} at {math.degrees(angle):.1f} deg is past its limits '
                        f'[{math.degrees(joint.min_angle_rad):.1f}, '
                        f'{math.degrees(joint.max_angle_rad):.1f}] deg')
        return None

    def tracking_failed(self, now_s: float, tracking_error_rad) -> Optional[str]:
        """Why control has failed by the tracking-error rule, or None."""
        worst = float(np.max(np.abs(tracking_error_rad)))
        if worst <= self.config.tracking_error_limit_rad:
            self.over_limit_since_s = None
            return None
        if self.over_limit_since_s is None:
            self.over_limit_since_s = now_s
        if now_s - self.over_limit_since_s < self.config.tracking_error_time_s:
            return None
        return (f'tracking error {math.degrees(worst):.1f} deg above '
                f'{math.degrees(self.config.tracking_error_limit_rad):.1f} deg for '
                f'{self.config.tracking_error_time_s:g} s')

    def far_off(self, tracking_error_rad) -> bool:
        """Off the motion by more than ``OFF_PLAN_SHARE`` of the tracking-error limit."""
        return float(np.max(np.abs(tracking_error_rad))) > \
            OFF_PLAN_SHARE * self.config.tracking_error_limit_rad

    def resume(self, now_s: float, state, commanded_q, lost=None) -> tuple[Motion, str]:
        """The motion that takes control back at ``state`` (the estimate [q, q̇]), last
        commanded at ``commanded_q`` (None if never), and a sentence saying what it does;
        ``lost``: the motion the sensors were lost on, when that is why control stopped."""
        q, qd = np.asarray(state[:2], float), np.asarray(state[2:], float)
        self.over_limit_since_s = None
        if lost is not None:                # a motion under way: its setpoint is no hold
            stop = self._stop(now_s, q, qd)
            if stop is not None:
                return stop, ('moving: braking from where it is, in a straight line, while '
                              'the goal is planned again from there')
            again = lost.rejoined(now_s, q, qd, REJOIN_RAD, REJOIN_RAD_S, MOVING_RAD_S)
            if again is not None:
                return again, 'still on its plan, which goes on from there'
        if commanded_q is not None:
            commanded_q = np.asarray(commanded_q, float)
            sag = float(np.max(np.abs(commanded_q - q)))
            if 0.0 < sag <= RETURN_REACH_RAD and self.forbidden.segment_is_free(q, commanded_q):
                step = np.degrees(commanded_q - q)
                return (self._move(now_s, q, commanded_q),
                        f'back to where it was held, ({step[0]:+.1f}, {step[1]:+.1f}) deg away')
        margin = self.arm.world.clearance_rad
        if margin <= 0.0 or self.forbidden.clear_by(q, margin):
            stop = self._stop(now_s, q, qd)
            if stop is not None:
                return stop, 'moving: braking from where it is, in a straight line, to hold there'
            return Motion(HoldTrajectory(q), now_s), 'holding where it is'
        target = self.forbidden.nearest_clear(q, margin, LIFT_REACH_RAD)
        if target is None:
            return (Motion(HoldTrajectory(q), now_s),
                    f'in or within {math.degrees(margin):.1f} deg of forbidden space and no '
                    'short move lifts it clear: holding there; the next goal leaves along its '
                    'plan')
        step = np.degrees(target - q)
        return (self._move(now_s, q, target),
                f'within {math.degrees(margin):.1f} deg of forbidden space: lifting it clear '
                f'by ({step[0]:+.1f}, {step[1]:+.1f}) deg, holding there')

    def _stop(self, now_s, q, qd) -> Optional[Motion]:
        """Brake to rest from (q, q̇) within 1/``STOP_MARGIN`` of what the motors surely
        give from rest (at speed the arm's own dynamics take some), when the arm moves and
        the straight line it stops along is free: holding a point it is flying past, or a
        plan it is behind at the motors' limits, would leave it beyond what the feedback
        catches."""
        if np.max(np.abs(qd)) <= MOVING_RAD_S:
            return None
        stop = StraightStop(q, qd, now_s, self.max_acceleration / STOP_MARGIN)
        return stop if self.forbidden.segment_is_free(q, stop.final_q) else None

    def _move(self, now_s, q0, q1) -> Motion:
        return StraightMove(q0, q1, now_s, self.max_acceleration, self.max_velocity)


def sure_limits(dynamics, forbidden, arm: ArmConfig, config: ControllerConfig):
    """(speed, acceleration) per joint that braking, holds and driver mode may count on:
    what the motors surely give in any free pose within the trajectory's volts (the battery
    less the reserves) -- no more than the free speed, and the least favourable pose's
    acceleration -- within the configured caps."""
    volts = min(TrajectoryLimits.from_config(arm, config).budget)
    return (np.minimum(config.max_velocity_rad_s, dynamics.free_speed_rad_s(volts)),
            np.minimum(config.max_acceleration_rad_s2,
                       sure_acceleration_rad_s2(dynamics, forbidden, volts)))
