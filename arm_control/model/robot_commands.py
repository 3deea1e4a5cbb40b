"""The commands a robot holds, and the volts it applies at an instant.

Commands wait from their arrival until the robot takes them (``take``, at its loop's
instant, or at once when it applies them on arrival): never before they arrived. The latest
taken is in charge: a plain voltage pair, applied as it is until ``timeout_s`` after it
arrived, then 0 V (WPILib's MotorSafety); or a profile, played on the robot's reading
(``ProfilePlayer``) until a newer command takes over. A profile does not time out: it ends
at rest with its holding volts, and past its end it holds there (model/profile.py).
"""

import math

from arm_control.model.profile import Profile, ProfilePlayer

ZERO_V = (0.0, 0.0)


class RobotCommands:
    """Commands in (``arrive``), taken at an instant (``take``), volts out (``volts``)."""

    def __init__(self, max_voltage: float, timeout_s: float):
        self.player = ProfilePlayer(max_voltage)
        self.timeout_s = float(timeout_s)
        self.waiting = []                   # (arrived s, pair or Profile), in arrival order
        self.pair, self.pair_s = ZERO_V, -math.inf     # the last plain command, its arrival
        self.playing = False                # a profile is in charge
        self.taken = 0                      # commands taken so far
        self.late = 0                       # profiles taken after their first setpoint's instant

    def arrive(self, arrived_s: float, command) -> None:
        """A decoded command (``profile.decode_command``) arrived at ``arrived_s``."""
        self.waiting.append((float(arrived_s), command))

    def take(self, t_s: float) -> int:
        """Take the commands that arrived by ``t_s``; how many."""
        taken = [c for c in self.waiting if c[0] <= t_s]
        self.waiting = [c for c in self.waiting if c[0] > t_s]
        for arrived_s, command in taken:
            if isinstance(command, Profile):
                self.late += t_s > command.start_s + 0.5 * command.step_s
                self.player.offer(command)
                self.playing = True
            else:
                self.player.clear()
                self.pair, self.pair_s, self.playing = tuple(command), arrived_s, False
        self.taken += len(taken)
        return len(taken)

    def timed_out(self, t_s: float) -> bool:
        """A plain command is in charge and is older than the timeout (or none came)."""
        return not self.playing and t_s - self.pair_s > self.timeout_s

    def volts(self, t_s: float, position_rad, velocity_rad_s) -> tuple[float, float]:
        """What the robot applies from ``t_s``, with its reading (q, q̇) of that instant. A
        profile not begun yet leaves the command before it in charge."""
        if self.playing:
            played = self.player.volts(t_s, position_rad, velocity_rad_s)
            if played is not None:
                return played
        return ZERO_V if t_s - self.pair_s > self.timeout_s else self.pair
