"""The control loop's beat: ``tick`` once per period on the node's clock, in a thread of its
own at real-time priority where allowed, so that no callback, burst of messages, graph change
or busy process delays a command. A plan that becomes ready wakes it at once (``poke``): the
motion starts then, not at the next period, and the periods run on from there.

In simulated time the sim steps once per command, so a tick is an answer to one step: it
waits (up to ``SIM_INPUT_WAIT_S`` of wall time) until ``has_input(now)`` says the step's
reading is in, rather than answer on the reading before; and it is never poked, since an
extra command would put every later one a period behind the state it was computed for."""

import threading
import time

from rclpy.clock import ClockType

from arm_control.nodes.realtime import raise_this_thread

# With simulated time the clock only moves when /clock does: look this often (wall s).
SIM_TIME_POLL_S = 0.001
# With simulated time, a due tick waits at most this long (wall s) for the step's reading.
SIM_INPUT_WAIT_S = 0.02
# A tick is due this close to its time: a clock of ~1e9 s in float seconds is exact to ~1e-7 s,
# and in simulated time a step's time a hair early would leave the sim waiting on the tick.
DUE_SLACK_S = 1e-4
# The clock's rate is measured over this much wall time.
RATE_WINDOW_S = 0.5
RATE_MEMORY = 4


class ClockRate:
    """Seconds of the node's clock per wall second: 1 in real time, 5 with the sim at 5x;
    the most of the last ``RATE_MEMORY`` windows, since a sim in step with a slow process
    runs slower now and then, and a budget in wall time must not shrink with it. Windows in
    which the clock stood still (a paused sim) are left out."""

    def __init__(self):
        self.rate = 1.0
        self._rates = []
        self._since = None                   # (clock s, wall s) at the window's start

    def update(self, clock_s: float, wall_s: float) -> float:
        if self._since is None:
            self._since = (clock_s, wall_s)
        clock0, wall0 = self._since
        if wall_s - wall0 >= RATE_WINDOW_S:
            if clock_s > clock0:
                self._rates = (self._rates + [(clock_s - clock0) / (wall_s - wall0)])[
                    -RATE_MEMORY:]
                self.rate = max(self._rates)
            self._since = (clock_s, wall_s)
        return self.rate


class ControlLoop:
    """Calls ``tick()`` every ``period_s`` of ``clock`` time, and at once when poked;
    ``priority_problem`` says why the thread could not run at ``realtime_priority``;
    ``clock_rate`` is the clock's seconds per wall second."""

    def __init__(self, clock, period_s: float, tick, realtime_priority: int = 0, warn=print,
                 has_input=lambda now_s: True):
        self.clock, self.period_s, self.tick = clock, period_s, tick
        self.has_input = has_input
        self.realtime_priority, self.warn = realtime_priority, warn
        self.priority_problem = None
        self.rate = ClockRate()
        self._wake = threading.Event()
        self._stopping = False
        self._thread = threading.Thread(target=self._run, daemon=True, name='control loop')

    def now_s(self) -> float:
        return self.clock.now().nanoseconds * 1e-9

    @property
    def clock_rate(self) -> float:
        return self.rate.rate

    def start(self) -> None:
        self._thread.start()

    def poke(self) -> None:
        """Tick now, and count the periods on from here (in real time)."""
        if not self._simulated():
            self._wake.set()

    def stop(self) -> None:
        self._stopping = True
        self._wake.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(1.0)

    def _simulated(self) -> bool:
        return self.clock.clock_type == ClockType.ROS_TIME and self.clock.ros_time_is_active

    def _run(self) -> None:
        self.priority_problem = raise_this_thread(self.realtime_priority)
        if self.priority_problem:
            self.warn(self.priority_problem)
        due_s = self.now_s()
        waiting_since = None                # wall s a due simulated tick began to wait
        while not self._stopping:
            now, wall = self.now_s(), time.monotonic()
            self.rate.update(now, wall)
            poked = self._wake.is_set()
            due = now >= due_s - DUE_SLACK_S
            if not poked and due and self._simulated() and not self.has_input(now):
                waiting_since = wall if waiting_since is None else waiting_since
                if wall - waiting_since < SIM_INPUT_WAIT_S:
                    self._wake.wait(SIM_TIME_POLL_S)
                    continue
            waiting_since = None
            if poked or due:
                self._wake.clear()
                if self._stopping:
                    return
                self.tick()
                # On time: keep the phase. Poked, or a whole period late: a new phase. In
                # simulated time the phase is the sim's steps: once per step, never twice for
                # one (a clock two steps on must not leave a tick due at the same time).
                late = poked or now > due_s + self.period_s or self._simulated()
                due_s = (now if late else due_s) + self.period_s
                continue
            wait_s = due_s - now
            if self._simulated():
                wait_s = min(wait_s, SIM_TIME_POLL_S)
            self._wake.wait(wait_s)
