"""The operator's stops: cancel, e-stop, reset, enable and disable.

An e-stop by service brakes to rest along the path and holds there (``estop_holds_arm``:
with no brake, 0 V drops a 45 kg arm); control that has failed stops at 0 V (its sensors
lost, the robot plays the rest of its last profile: ``robot_command``). Taking the arm back
after 0 V is ``Recovery.resume``.
"""

from arm_control.control.events import EventKind as Kind
from arm_control.control.state_machine import ArmState as S, COMMANDING, STOPPED, Trigger as T


class Stops:
    """Whether the arm is held or at 0 V while stopped, and why it was e-stopped."""

    def __init__(self, config, machine, goals, setpoints, events, recovery, pid):
        self.config, self.machine, self.goals, self.setpoints = config, machine, goals, setpoints
        self.events, self.recovery, self.pid = events, recovery, pid
        self.estop_holding = False                        # e-stopped, holding (not at 0 V)
        self.held_by_robot = False      # ... its sensors then lost: the robot plays the rest
        self.estop_error, self.estops = '', 0

    def lost_while_holding(self, now_s: float, age_s: float) -> None:
        """Sensors lost while an e-stop holds the arm: 0 V (sending profiles, the robot
        plays the rest of the last, held)."""
        self.held_by_robot = self.config.command_mode == 'profile'
        self.estop(now_s, f'no joint states for {age_s:.3f} s while holding', cut_power=True)

    def cancel(self, now_s: float) -> tuple[bool, str]:
        """Clear the queue and the current goal; brake to rest along the path and hold."""
        if self.machine.state in COMMANDING:
            self.setpoints.brake(now_s)
        dropped = self.goals.drop()
        if self.machine.can(T.CANCEL):
            self.machine.fire(T.CANCEL)
        message = f'cancelled: {dropped} goals dropped; holding'
        self.events.say(now_s, Kind.CANCELLED, 'info', message, count=dropped)
        return True, message

    def estop(self, now_s: float, reason: str = 'e-stop requested',
              cut_power: bool = False) -> tuple[bool, str]:
        """Stopped until ``reset``, the queue cleared: braked to rest along the path and held
        there (``estop_holds_arm``, and the arm under control), else -- ``cut_power``, or
        e-stopped again while held -- 0 V. ``cut_power``: control itself failed."""
        hold = self.config.estop_holds_arm and not cut_power and self.machine.state in COMMANDING
        if self.machine.state == S.ESTOPPED:
            if not self.estop_holding and self.held_by_robot:   # the robot held it: 0 V
                self.held_by_robot = False
                return self._say(now_s, Kind.ESTOP, 'error', 'E-STOP again: 0 V until reset')
            if not self.estop_holding:
                return True, 'already e-stopped: 0 V until reset'
        else:
            if hold:
                self.setpoints.brake(now_s)
            self.goals.drop()
            self.machine.fire(T.ESTOP)
            self.estops += 1
        self.estop_holding = hold
        if not hold:
            self.pid.reset()
        self.estop_error = f'E-STOP: {reason}'
        action = ('braking to rest and holding there until reset (e-stop again: 0 V)' if hold
                  else 'the robot plays the rest of the last profile, held, until reset '
                  '(e-stop again: 0 V)' if self.held_by_robot else '0 V until reset')
        kind = Kind.CONTROL_FAILED if cut_power else Kind.ESTOP
        return self._say(now_s, kind, 'error', f'E-STOP: {reason}; {action}')

    @property
    def unpowered(self) -> bool:
        """Stopped at 0 V: e-stopped (and not holding), disabled or in error."""
        return self.machine.state in STOPPED and not self.estop_holding

    def reset(self, now_s: float) -> tuple[bool, str]:
        """Clear an e-stop or an error; a held arm keeps its hold, one at 0 V is taken back."""
        if not self.machine.can(T.RESET):
            return False, f"nothing to reset in state '{self.machine.state}'"
        previous, holding = self.machine.state, self.estop_holding or self.machine.state == S.ERROR
        self.machine.fire(T.RESET)
        self.estop_holding, self.estop_error, self.goals.last_error = False, '', ''
        self.held_by_robot = False
        what = 'holding where it was held' if holding else self.recovery.resume(now_s)
        return self._say(now_s, Kind.RESET, 'info', f'reset from {previous}: {what}')

    def enable(self, now_s: float, enabled: bool) -> tuple[bool, str]:
        """Enable (take the arm back) or disable (0 V, goals dropped)."""
        if enabled:
            if self.machine.state != S.DISABLED:
                return True, f"already enabled (state '{self.machine.state}')"
            self.machine.fire(T.ENABLE)
            return self._say(now_s, Kind.ENABLED, 'info',
                             f'enabled: {self.recovery.resume(now_s)}')
        if self.machine.state == S.DISABLED:
            return True, 'already disabled'
        if not self.machine.can(T.DISABLE):
            return False, f"cannot disable in state '{self.machine.state}': reset first"
        self.goals.drop()
        self.machine.fire(T.DISABLE)
        self.held_by_robot = False
        self.pid.reset()
        return self._say(now_s, Kind.DISABLED, 'info', 'disabled: 0 V, goals dropped')

    def _say(self, now_s: float, kind: Kind, level: str, message: str) -> tuple[bool, str]:
        self.events.say(now_s, kind, level, message)
        return True, message
