"""How late things are: when a reading was taken, and when a command will act, on the
controller's clock. Through ROS both differ from the moment the controller handles them by
milliseconds that matter to a time-optimal move; the controller works at the instant its
command acts, with the state estimated for it.
"""

from collections import deque
import math
import statistics

# A reading is timed over the least transit of this many (a second at 50 Hz) ...
TRANSIT_WINDOW = 50
# ... and at most this long before it arrived, whatever its stamp says.
MAX_TRANSIT_S = 0.05
# A command's compute is taken as the median of this many ticks ...
COMPUTE_WINDOW = 25
# ... and its way to the motors as this: the sim hears a command 0.8-1.5 ms after it was
# sent (its diagnostics' "command transit median", each second of the suite on one host).
COMMAND_TRANSIT_S = 0.001


class ReadingClock:
    """When each reading was taken, on our clock: at its stamp, as ROS means it, where the
    stamps are on our clock -- the least transit (arrival − stamp) of the last
    ``TRANSIT_WINDOW`` readings is between 0 and ``MAX_TRANSIT_S`` -- and else at its stamp
    shifted by that least transit (another host's clock mapped onto ours); never after its
    arrival and at most ``MAX_TRANSIT_S`` before it. Timed at their arrival, readings that
    came 4 ms late (9 ms at p90, through ROS on an idle machine) left the estimate behind
    the arm by as much motion: in one process that delay made a move settle 45-70 ms later."""

    def __init__(self, window: int = TRANSIT_WINDOW):
        self.transits_s = deque(maxlen=window)

    def taken_s(self, stamp_s: float, arrival_s: float) -> float:
        if not math.isfinite(stamp_s):
            return arrival_s
        self.transits_s.append(arrival_s - stamp_s)
        least = min(self.transits_s)
        shift = 0.0 if 0.0 <= least <= MAX_TRANSIT_S else least
        return min(max(stamp_s + shift, arrival_s - MAX_TRANSIT_S), arrival_s)


class CommandDelay:
    """How long after a tick begins its command acts: the tick's compute up to the publish
    (the median of the last ``COMPUTE_WINDOW``) and the command's transit, at most a period.
    The controller computes each command for that instant -- the state predicted to it, the
    trajectory sampled there. In one process, commands acting 10 ms late made "mid → stow"
    settle 0.54-0.59 s after its goal instead of 0.46-0.50 s; computed for when they act,
    0.47 s. Through ROS, during a move, a tick's command went out after 3.7 ms of CPU at the
    median (6.1 ms at p90)."""

    def __init__(self, period_s: float):
        self.period_s = period_s
        self.compute_s = deque(maxlen=COMPUTE_WINDOW)

    def sent(self, compute_s: float) -> None:
        """A tick's command went out ``compute_s`` after the tick began."""
        if math.isfinite(compute_s) and compute_s >= 0.0:
            self.compute_s.append(compute_s)

    @property
    def delay_s(self) -> float:
        compute = statistics.median(self.compute_s) if self.compute_s else 0.0
        return min(compute + COMMAND_TRANSIT_S, self.period_s)
