"""Control time from a clock that may jump: continuous, never backwards.

A node's clock can jump: in simulated time any process may publish ``/clock`` (a rogue
message 100 s ahead, a restarted sim 10 s back), and the system clock can be stepped. A
control loop that schedules itself on such a clock waits 100 s for its next tick, or takes
every reading as 100 s old and stops commanding. So the loop runs on control time:

    control = clock + offset,

and a jump of the clock -- a step back of more than ``BACK_SLACK_S``, or a step forward of
more than ``FORWARD_JUMP_S`` and more than ``MAX_RATE`` times the wall time since the last
reading of it -- is taken out of the offset: control time stands still across the jump and
goes on at the clock's rate from there. A clock stamp (a reading's) is put on control time
with the same offset. Each jump is kept for the node to say (``take``).
"""

import threading

# A step forward is a jump beyond this (s of the clock) ...
FORWARD_JUMP_S = 1.0
# ... and beyond this many times the wall time it took: the sim's fastest clock
# (``sim_time_factor`` is at most 100), with room.
MAX_RATE = 200.0
# A step back beyond this is a jump (s); within it, control time waits for the clock.
BACK_SLACK_S = 0.001


class ClockGuard:
    """``now_s()``: control time (s), from ``source()`` -> (clock s, wall s), read under a
    lock (read outside it, a thread preempted between its reading and its turn would bring
    an old reading: a false step back)."""

    def __init__(self, source):
        self.source = source
        self.offset_s = 0.0
        self._last = None               # (clock s, wall s) at the last read
        self._control_s = None          # the last control time returned
        self._jumps = []                # clock steps taken out, not yet taken
        self.jumps = 0
        self._lock = threading.Lock()

    def now_s(self) -> float:
        """Control time now; a clock at 0 or less (simulated time before the first /clock)
        is passed through."""
        with self._lock:
            clock_s, wall_s = self.source()
            if clock_s <= 0.0:
                return clock_s
            if self._last is not None:
                step_s = clock_s - self._last[0]
                elapsed_s = max(wall_s - self._last[1], 0.0)
                if step_s < -BACK_SLACK_S or \
                        step_s > max(FORWARD_JUMP_S, MAX_RATE * elapsed_s):
                    self.offset_s -= step_s
                    self._jumps.append(step_s)
                    self.jumps += 1
            self._last = (clock_s, wall_s)
            control_s = clock_s + self.offset_s
            if self._control_s is not None and control_s < self._control_s:
                control_s = self._control_s
            self._control_s = control_s
            return control_s

    def to_control_s(self, stamp_s: float) -> float:
        """A stamp of the clock, on control time."""
        return stamp_s + self.offset_s

    def take(self) -> list:
        """The clock steps (s) taken out since the last call."""
        with self._lock:
            jumps, self._jumps = self._jumps, []
        return jumps
