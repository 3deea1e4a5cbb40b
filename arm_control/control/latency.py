"""When a command will act, on the controller's clock. Through ROS it acts milliseconds
after the tick that computed it, which matters to a time-optimal move; the controller works
at that instant, with the state estimated for it.
"""

from collections import deque
import math
import statistics

# A command's compute is taken as the median of this many ticks ...
COMPUTE_WINDOW = 25
# ... and its way to the motors as this: about a millisecond on one host (the sim's
# diagnostics report the median as "command transit median").
COMMAND_TRANSIT_S = 0.001


class CommandDelay:
    """How long after a tick begins its command acts: the tick's compute up to the publish
    (the median of the last ``COMPUTE_WINDOW``) and the command's transit, at most a period.
    The controller computes each command for that instant -- the state predicted to it, the
    trajectory sampled there -- so that a command that acts late does not leave the arm behind
    its plan and overshooting as it catches up (``test_latency.py``)."""

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
