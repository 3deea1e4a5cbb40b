"""The control loop's beat: ``tick`` once per period on the node's clock, in a thread of its
own at real-time priority where allowed, so that no callback, burst of messages, graph change
or busy process delays a command. A plan that becomes ready wakes it at once (``poke``): the
motion starts then, not at the next period, and the periods run on from there. In real time
``align(due_s)`` moves each next tick (the node's: to just after the robot loop's instants,
``Commander.tick_due``), and ``periods()`` says how many periods on it is due (the node's:
``holding_periods`` while the arm holds still, else one).

In simulated time the sim steps once per command, so a tick is an answer to one step: it
waits (up to ``SIM_INPUT_WAIT_S`` of wall time) until ``has_input(now)`` says the step's
reading is in, rather than answer on the reading before; and it is never poked, since an
extra command would put every later one a period behind the state it was computed for.
While ``working()`` (wall-time work under way: a plan being made and timed in other
processes), it answers a step no sooner than a period of wall time after the last. The sim,
in step with it, then keeps to real time, and the work costs the arm as much simulated time
as it would cost real time: planning's wall time had shown up 2-5 times longer on a faster
clock, and the moves took 1.36-1.41x their minimum there against 1.24x in real time. Budgets
of wall time (the planner timeout, a plan's lead) hold on the clock as they are.

The clock is read through a ``ClockGuard``: its jumps (a rogue /clock, a restarted sim) are
taken out, so the loop's time never leaps or goes back. A clock that stops while readings
still come (something else holds /clock) does not stop the loop: after
``CLOCK_STOPPED_WALL_S`` of wall time it answers the readings on the clock as it stands."""

import threading
import time

from rclpy.clock import ClockType

from arm_control.control.clock_guard import ClockGuard
from arm_control.realtime import raise_this_thread

# With simulated time the clock only moves when /clock does: look this often (wall s).
SIM_TIME_POLL_S = 0.001
# With simulated time, a due tick waits at most this long (wall s) for the step's reading.
SIM_INPUT_WAIT_S = 0.02
# With simulated time, a reading is answered after this long (wall s) without the clock.
CLOCK_STOPPED_WALL_S = 0.5
# A tick is due this close to its time: a clock of ~1e9 s in float seconds is exact to ~1e-7 s,
# and in simulated time a step's time a hair early would leave the sim waiting on the tick.
DUE_SLACK_S = 1e-4


class ControlLoop:
    """Calls ``tick()`` every ``period_s`` of ``clock`` time, and at once when poked;
    ``priority_problem`` says why the thread could not run at ``realtime_priority``."""

    def __init__(self, clock, period_s: float, tick, realtime_priority: int = 0, warn=print,
                 has_input=lambda now_s: True, working=lambda: False, align=lambda due_s: due_s,
                 periods=lambda: 1):
        self.clock, self.period_s, self.tick = clock, period_s, tick
        self.has_input, self.working, self.align = has_input, working, align
        self.periods = periods
        self.realtime_priority, self.warn = realtime_priority, warn
        self.priority_problem = None
        self.last_tick_s = None             # the clock's time at the last tick
        # Control time: the clock with its jumps taken out (``ClockGuard``).
        self.guard = ClockGuard(lambda: (self._clock_ns() * 1e-9, time.monotonic()))
        self.clock_stops = 0                # ticks on a reading, the clock stopped
        self._wake = threading.Event()
        self._stopping = False
        self._thread = threading.Thread(target=self._run, daemon=True, name='control loop')

    def now_s(self) -> float:
        return self.guard.now_s()

    def arrived_s(self, received_ns: int) -> float:
        """When a message taken now had come, on control time: in real time the instant the
        middleware received it (``received_ns``, the system clock's, as the node's), not
        after now; in simulated time, or with no such instant, now."""
        now = self.now_s()
        if received_ns <= 0 or self.simulated():
            return now
        return min(now, self.guard.to_control_s(received_ns * 1e-9))

    def _clock_ns(self) -> int:
        """The clock's time (ns), as ``clock.now()``; from an rclpy clock's handle, without
        making a Time of it (read several times a period)."""
        handle = getattr(self.clock, 'handle', None)
        if handle is None:
            return self.clock.now().nanoseconds
        with handle:
            return handle.get_now().nanoseconds

    def started(self) -> bool:
        """The clock runs. With simulated time it reads 0 until the first /clock: a reading
        or a tick stamped then, and the next an epoch later, once overflowed the filter's
        prediction, and the controller never left ``no_sensors`` (seen under load)."""
        return self._clock_ns() > 0

    def next_command_s(self) -> float:
        """When the next command will act: now in real time (a poke ticks at once); in
        simulated time the next step, once this one is answered (the sim is on it)."""
        now = self.now_s()
        if self.simulated() and self.last_tick_s is not None \
                and now <= self.last_tick_s + DUE_SLACK_S:
            return self.last_tick_s + self.period_s
        return now

    def start(self) -> None:
        self._thread.start()

    def poke(self) -> None:
        """Tick now, and count the periods on from here (in real time)."""
        if not self.simulated():
            self._wake.set()

    def stop(self) -> None:
        self._stopping = True
        self._wake.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(1.0)

    def simulated(self) -> bool:
        return self.clock.clock_type == ClockType.ROS_TIME and self.clock.ros_time_is_active

    def _run(self) -> None:
        self.priority_problem = raise_this_thread(self.realtime_priority)
        if self.priority_problem:
            self.warn(self.priority_problem)
        due_s = self.now_s()
        waiting_since = None                # wall s a due simulated tick began to wait
        last_tick_wall = -float('inf')
        jumps_seen = self.guard.jumps
        while not self._stopping:
            now, wall = self.now_s(), time.monotonic()
            if now <= 0.0:                  # simulated time before the first /clock
                self._wake.wait(SIM_TIME_POLL_S)
                continue
            poked = self._wake.is_set()
            if self.guard.jumps != jumps_seen:
                # Across a jump of the clock control time stood still: its step is due now.
                jumps_seen, due_s = self.guard.jumps, now
            due = now >= due_s - DUE_SLACK_S
            if not poked and due and self.simulated():
                waiting_since = wall if waiting_since is None else waiting_since
                starved = not self.has_input(now) and wall - waiting_since < SIM_INPUT_WAIT_S
                held = wall - last_tick_wall < self.period_s and self.working()
                if starved or held:
                    self._wake.wait(SIM_TIME_POLL_S)
                    continue
            waiting_since = None
            # The clock stopped while readings come: answer them on the clock as it is (a
            # paused sim stops both, and nothing is sent).
            stopped = self.simulated() and not due and self.has_input(now) \
                and wall - last_tick_wall > CLOCK_STOPPED_WALL_S
            if stopped:
                self.clock_stops += 1
                if self.clock_stops % 20 == 1:
                    self.warn(f'the clock stopped while joint states come: answering them '
                              f'({self.clock_stops} times so far)')
            if poked or due or stopped:
                self._wake.clear()
                if self._stopping:
                    return
                last_tick_wall, self.last_tick_s = wall, now
                self.tick()
                # On time: keep the phase. Poked, or a whole period late: a new phase. In
                # simulated time the phase is the sim's steps: once per step, never twice for
                # one (a clock two steps on must not leave a tick due at the same time).
                late = poked or now > due_s + self.period_s or self.simulated()
                due_s = (now if late else due_s) + self.period_s
                if not self.simulated():
                    due_s = self.align(due_s + (self.periods() - 1) * self.period_s)
                continue
            wait_s = due_s - now
            if self.simulated():
                wait_s = min(wait_s, SIM_TIME_POLL_S)
            self._wake.wait(wait_s)
