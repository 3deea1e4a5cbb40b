"""What is fresh and what is allowed, on the bridge's side of the link (``RobotLink``): the
controller's commands go to the robot only while its readings are fresh and it is enabled;
a lost robot is sent nothing (it stops by its own rule), any other 0 V. The controller is
disabled and enabled with the robot. (The robot's side: ``robot_loop``.)
"""

from dataclasses import dataclass
from enum import Enum
import math

ZERO_V = (0.0, 0.0)


class LinkState(str, Enum):
    CONNECTING = 'connecting'       # no reading from the robot yet: 0 V
    ENABLED = 'enabled'             # fresh readings, robot enabled: the controller commands it
    DISABLED = 'disabled'           # fresh readings, robot disabled: 0 V
    LOST = 'lost'                   # no reading for reading_timeout_s: nothing sent

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class LinkEvent:
    """A change of the link's state: its level ('info', 'warning', 'error'), its words, and
    what the controller should be told (enabled True or False; None: nothing)."""

    state: LinkState
    level: str
    message: str
    controller_enabled: bool | None
    previous: LinkState | None = None       # the state it left (connecting: found; lost: back)
    silent_s: float | None = None           # lost: how long no reading had come (awake time)
    nt_connected: bool | None = None        # lost: whether NT still reported the connection


class RobotLink:
    """The bridge's view of the robot, on the bridge's clock (seconds).

    The robot is lost when NT reports the connection down, or when no reading has come for
    ``reading_timeout_s`` of the bridge's own *awake* time: each ``check`` adds the time
    since the last one, but at most ``max_credit_s``, so a bridge that was starved of the
    processor (its readings waiting in its socket) does not blame the robot for its own
    sleep. A stamp that goes back (a restarted robot) counts as a reading like any other.

    The controller follows the robot's enable. A lost robot does not disable it: its joint
    states stop, so it stops commanding on its own (after ``joint_state_timeout_s``) and
    carries on with its goals when they return, as after any loss of its sensors.
    """

    def __init__(self, reading_timeout_s: float, max_credit_s: float = 0.04):
        if not reading_timeout_s > 0.0:
            raise ValueError(f'reading timeout must be > 0 s, got {reading_timeout_s}')
        self.reading_timeout_s = reading_timeout_s
        self.max_credit_s = max_credit_s
        self.state = LinkState.CONNECTING
        self.last_reading_s = -math.inf
        self.awake_s = 0.0                  # the bridge's awake time, summed by check()
        self.awake_at_reading_s = 0.0
        self.checked_s = None

    @property
    def may_command(self) -> bool:
        """Only a fresh, enabled robot is sent the controller's voltages."""
        return self.state == LinkState.ENABLED

    @property
    def silent_s(self) -> float:
        """The bridge's awake time since the last reading."""
        return self.awake_s - self.awake_at_reading_s

    def outgoing(self, voltage) -> tuple[float, float] | None:
        """The voltage to send: the controller's while the robot may be commanded; None (send
        nothing) while it is lost; else 0 V. A lost link may only have stalled: what is sent
        into it arrives when it recovers, and 0 V would then drop an arm the robot holds at
        its last profile's end (its rule when commands stop)."""
        if self.state == LinkState.LOST:
            return None
        return tuple(voltage) if self.may_command else ZERO_V

    def on_reading(self, now_s: float, robot_enabled: bool) -> LinkEvent | None:
        """A reading arrived, with the robot's enabled flag."""
        self.last_reading_s = now_s
        self.awake_at_reading_s = self.awake_s
        state = LinkState.ENABLED if robot_enabled else LinkState.DISABLED
        if state == self.state:
            return None
        prefix = {LinkState.CONNECTING: 'robot found, ',
                  LinkState.LOST: 'robot back, '}.get(self.state, 'robot ')
        previous, self.state = self.state, state
        if state == LinkState.ENABLED:
            return LinkEvent(state, 'info', f'{prefix}enabled: the controller is enabled',
                             True, previous)
        return LinkEvent(state, 'warning', f'{prefix}disabled: 0 V, the controller is disabled',
                         False, previous)

    def check(self, now_s: float, nt_connected: bool) -> LinkEvent | None:
        """The connection is down, or no reading for reading_timeout_s of awake time: lost."""
        if self.checked_s is not None:
            self.awake_s += min(max(now_s - self.checked_s, 0.0), self.max_credit_s)
        self.checked_s = now_s
        if self.state in (LinkState.LOST, LinkState.CONNECTING):
            return None
        if nt_connected and self.silent_s <= self.reading_timeout_s:
            return None
        previous, self.state = self.state, LinkState.LOST
        why = (f'no readings for {self.silent_s:.2f} s (NT still connected)' if nt_connected
               else 'NT disconnected')
        return LinkEvent(LinkState.LOST, 'error',
                         f'lost the robot: {why}: no commands until it is back (it holds where '
                         'its last profile ends); the controller stops as its joint states do',
                         None, previous, self.silent_s, nt_connected)
