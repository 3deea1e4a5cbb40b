"""Taking control back: where the arm was commanded, and what to do when it is not there.

After 0 V, sensors lost and back, a jump of the sensors, or an arm far off the motion it
follows, control resumes through ``SafetyRules.resume``: brake an arm that moves, return it
to where it was held, or lift it clear of forbidden space.
"""

from typing import Optional

import numpy as np

from arm_control.control.events import EventKind as Kind
from arm_control.control.safety import LEAVES_UNTIL_REACHED
from arm_control.control.state_machine import ArmState as S, Trigger as T


class Recovery:
    """What control remembers of where it had the arm (``commanded_q``, the motion under
    way when the sensors went), and the moves that take it back."""

    def __init__(self, config, sensing, safety, setpoints, goals, machine, events, pid):
        self.config, self.sensing, self.safety = config, sensing, safety
        self.setpoints, self.goals, self.machine, self.events = setpoints, goals, machine, events
        self.pid = pid
        self.commanded_q: Optional[np.ndarray] = None    # the setpoint last commanded
        self.resume_motion = None                         # the last motion back after 0 V
        self.held_when_lost: Optional[np.ndarray] = None  # the goal held as sensors went
        self.lost_motion = None                   # ... or the motion under way then
        self.left_times, self.reached_when_left = 0, 0    # motions left since a goal reached

    def commanded(self, now_s: float, setpoint_q) -> None:
        """The setpoint commanded now; a motion back under way or braked: its end, not the
        sag it left."""
        back = self.resume_motion
        self.commanded_q = np.array(back.final_q if self.setpoints.in_charge(back, now_s)
                                    else setpoint_q, float)

    def resume(self, now_s: float, lost=None) -> str:
        """Take control back after 0 V (``SafetyRules.resume``); says what it does."""
        state = self.sensing.state if self.sensing.started else np.zeros(4)
        motion, what = self.safety.resume(now_s, state, self.commanded_q, lost)
        self.resume_motion = motion
        self.setpoints.driving = False
        self.setpoints.schedule(motion)
        self.goals.goal_q = None
        self.pid.reset()
        return what

    def sensors_lost(self, now_s: float, age_s: float) -> None:
        """No fresh joint states: the goal interrupted, resumed when they return."""
        self.held_when_lost = self.commanded_q if self.machine.state == S.HOLDING else None
        timeline = self.setpoints.timeline
        self.lost_motion = timeline.last if timeline.moving_at(now_s) else None
        self.goals.interrupt()
        self.machine.fire(T.SENSORS_LOST)
        self.goals.last_error = (f'no joint states for {age_s:.3f} s (limit '
                                 f'{self.config.joint_state_timeout_s:g} s)')
        action = ('the robot plays the rest of the last profile (to rest, held)'
                  if self.config.command_mode == 'profile' else 'sending 0 V')
        self.events.say(now_s, Kind.SENSORS_LOST, 'error',
                        f'{self.goals.last_error}: {action} until they return')

    def sensors_back(self, now_s: float) -> None:
        """Joint states again: back to the goal held, or resumed from where the arm is."""
        held, self.held_when_lost = self.held_when_lost, None
        lost, self.lost_motion = self.lost_motion, None
        what = self.resume(now_s, lost=lost)
        back_to_goal = held is not None and np.allclose(self.resume_motion.final_q, held)
        self.machine.fire(T.SENSORS_BACK_HELD if back_to_goal else T.SENSORS_BACK)
        if back_to_goal:
            self.goals.goal_q = held
        self.events.say(now_s, Kind.SENSORS_BACK, 'info', f'joint states arriving: {what}')

    def moved(self, now_s: float) -> None:
        """The sensors say the arm is far from where the filter had it (pushed, the sim
        reset): hold where it is now; an interrupted goal is planned again from there."""
        self.goals.interrupt()
        self.machine.fire(T.MOVED)
        self.commanded_q = None              # put there on purpose: no going back
        q = np.degrees(self.sensing.state[:2])
        self.events.say(now_s, Kind.ARM_MOVED, 'warning',
                        f'the arm is not where it was (moved, or the sim reset) at '
                        f'({q[0]:.1f}, {q[1]:.1f}) deg: {self.resume(now_s)}')

    def leave_motion(self, now_s: float, tracking_error_rad) -> bool:
        """Far off the motion it follows to a goal (its commands held up on the way, as DDS
        does for ~0.3 s when a node joins on a loaded machine; a push): a plan at the motors'
        limits leaves nothing to catch up with, so it brakes from where it is while the goal
        is planned again from there -- at most ``LEAVES_UNTIL_REACHED`` times before a goal
        is reached (not per goal: new goals must not keep an arm that cannot follow from the
        tracking-error rule), and past that the rule decides."""
        goal = self.goals.queue.current
        if self.machine.state not in (S.PLANNING, S.TRACKING) or goal is None \
                or not self.safety.far_off(tracking_error_rad):
            return False
        reached = self.goals.counts['reached']
        if reached != self.reached_when_left:
            self.left_times, self.reached_when_left = 0, reached
        if self.left_times >= LEAVES_UNTIL_REACHED:
            return False
        self.left_times += 1
        error = np.degrees(tracking_error_rad)
        lost = self.setpoints.timeline.last
        self.goals.interrupt()
        self.machine.fire(T.MOVED)
        self.events.say(now_s, Kind.OFF_PLAN, 'warning',
                        f'({error[0]:+.1f}, {error[1]:+.1f}) deg off its motion to '
                        f'{goal.label}: {self.resume(now_s, lost=lost)}')
        return True
