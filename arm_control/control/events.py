"""What the controller tells people: events with a kind, a level and a sentence.

Every goal gets an answer: queued, accepted, rejected, failed or reached. In a flood the
rejections beyond ``REJECTIONS_PER_WINDOW`` in a window are not said one by one: they are
counted by reason and said in one ``goals_rejected`` event per window, so none is lost
silently and a listener is not drowned. Text that came from outside (a preset's name, a
frame) is quoted by ``arm_control.text.quote``: at most a short prefix, with the length.
"""

from collections import deque
from dataclasses import dataclass
from enum import Enum
from typing import Optional

REJECTIONS_PER_WINDOW = 20
WINDOW_S = 1.0
HISTORY = 200


class EventKind(str, Enum):
    GOAL_QUEUED = 'goal_queued'
    GOAL_ACCEPTED = 'goal_accepted'            # taken now (a preset, a preempting goal)
    GOAL_REJECTED = 'goal_rejected'
    GOALS_REJECTED = 'goals_rejected'          # a window's rejections beyond the burst, counted
    GOAL_FAILED = 'goal_failed'                # no plan, no trajectory, planner timeout
    GOAL_REACHED = 'goal_reached'
    CANCELLED = 'cancelled'
    ESTOP = 'estop'                            # asked for (a service, a client)
    CONTROL_FAILED = 'control_failed'          # an e-stop at 0 V: control itself failed
    RESET = 'reset'
    ENABLED = 'enabled'
    DISABLED = 'disabled'
    SENSORS_LOST = 'sensors_lost'
    SENSORS_BACK = 'sensors_back'
    ARM_MOVED = 'arm_moved'                    # the sensors jumped: held where it now is
    OFF_PLAN = 'off_plan'                      # far off its motion: braked, planned again
    LIFTING_CLEAR = 'lifting_clear'            # a hold begins by lifting out of the margin
    NOT_CLEAR = 'not_clear'                    # ... and no short move could
    DRIVER = 'driver'
    DRIVER_IDLE = 'driver_idle'
    PLANNER_WAITING = 'planner_waiting'
    PLANNER_AVAILABLE = 'planner_available'
    PLANNER_GONE = 'planner_gone'
    PARAMETERS = 'parameters'                  # a setting changed at run time
    CLOCK_JUMPED = 'clock_jumped'              # taken out of control time (ClockGuard)
    UNTRUSTED = 'untrusted'                    # an input it cannot trust (cause: which)
    TRUSTED = 'trusted'                        # ... trusted again
    SENSORS_DISAGREE = 'sensors_disagree'      # a reading refused: the others say otherwise
    YIELDED = 'yielded'                        # another controller has the arm: sends nothing
    TAKEN_OVER = 'taken_over'                  # ... it went: this one takes the arm as it is

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class Event:
    """Something people should hear about."""

    time_s: float
    kind: EventKind
    level: str          # 'info', 'warning' (a goal rejected or failed), 'error' (e-stop)
    message: str
    cause: str = ''     # a few words to count and test by ('out of reach', 'queue full', ...)
    goal_xy_m: Optional[tuple[float, float]] = None    # the goal it is about, in arm_base
    count: int = 0      # how many: goals rejected in a window, goals dropped

    def __str__(self) -> str:
        """As published: 'kind: sentence', or 'kind (cause): sentence'."""
        cause = f' ({self.cause})' if self.cause else ''
        return f'{self.kind}{cause}: {self.message}'


def parse_event(text: str) -> tuple[str, str, str]:
    """(kind, cause, sentence) of an event as published (``str(event)``)."""
    head, _, message = text.partition(': ')
    kind, _, cause = head.partition(' (')
    return kind, cause.rstrip(')'), message


class EventLog:
    """Events as they happen; a window's rejections beyond the burst are counted instead."""

    def __init__(self):
        self.history: deque[Event] = deque(maxlen=HISTORY)
        self._new: list[Event] = []
        self._window_start_s = float('-inf')
        self._window_rejections = 0
        self._counted: dict[str, int] = {}        # reason -> rejections not said one by one
        self.said = 0                               # events said so far

    def say(self, now_s: float, kind: EventKind, level: str, message: str,
            cause: str = '', goal_xy_m: Optional[tuple[float, float]] = None,
            count: int = 0) -> Event:
        event = Event(now_s, kind, level, message, cause, goal_xy_m, count)
        self.history.append(event)
        self.said += 1
        self._new.append(event)
        del self._new[:-HISTORY]
        return event

    def reject(self, now_s: float, message: str, reason: str) -> None:
        """A goal rejected: said, unless the window has had its burst; then counted."""
        self.flush(now_s)
        self._window_rejections += 1
        if self._window_rejections <= REJECTIONS_PER_WINDOW:
            self.say(now_s, EventKind.GOAL_REJECTED, 'warning', message, reason)
        else:
            self._counted[reason] = self._counted.get(reason, 0) + 1

    def flush(self, now_s: float) -> None:
        """Close the window once it is over: one event with the count of what was counted."""
        if now_s - self._window_start_s < WINDOW_S:
            return
        if self._counted:
            total = sum(self._counted.values())
            reasons = '; '.join(f'{count} {reason}' for reason, count in self._counted.items())
            self.say(now_s, EventKind.GOALS_REJECTED, 'warning',
                     f'{total} more goals rejected in the last {now_s - self._window_start_s:.1f}'
                     f' s ({reasons})', count=total)
            self._counted = {}
        self._window_start_s, self._window_rejections = now_s, 0

    def since(self, said: int) -> tuple[Event, ...]:
        """The events said after the first ``said`` (as many as the history keeps)."""
        count = min(self.said - said, len(self.history))
        return tuple(self.history)[len(self.history) - count:] if count > 0 else ()

    @property
    def waiting(self) -> bool:
        """Events not yet taken."""
        return bool(self._new)

    def take(self) -> list[Event]:
        """Events since the last call (for the node to log and publish)."""
        out, self._new = self._new, []
        return out
