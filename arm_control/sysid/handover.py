"""Handing the arm over: after identification the arm is held, never left at 0 V.

An arm at 0 V falls (from the centre, a link is under the floor about a second later), and a
controller started "straight after" takes longer than that to come up. So ``sysid`` keeps
commanding: it holds the arm at the end of the excitation with the identified model (the
robot file's where nothing was written) until another node's commands arrive on
``voltage_command``, then stops publishing and exits; the new node commands from then on.
Another node is told from ``sysid`` by what it sends: a command ``sysid`` did not send
itself (the last ``REMEMBERED`` of its own are kept), ``TAKE_OVER_COMMANDS`` of them. A
publisher that is merely discovered does not count: it may not command yet, and the sim
would time out to 0 V in between.

With ``hand_over_timeout_s`` > 0 and no other node by then, the arm is lowered under
control onto ``rest_rad`` (a support the robot has there), held there ``REST_SETTLE_S``,
and only then left at 0 V.
"""

from collections import deque
import math

import numpy as np

from arm_control.config import ArmConfig
from arm_control.model.world import ForbiddenSpace
from arm_control.sysid.excitation import APPROACH_SPEED_RAD_S, Excitation, Part
from arm_control.sysid.segments import Hold, Quintic

REMEMBERED = 64            # own commands remembered, to tell another node's apart
TAKE_OVER_COMMANDS = 3     # another node's commands heard before the arm is left to it
REST_SETTLE_S = 1.0        # held on the rest this long before 0 V


class HandOver:
    """Who commands the arm: ``sent`` for every own command, ``heard`` for every command on
    the topic (own ones come back too); ``taken`` once another node commands it."""

    def __init__(self):
        self.own = deque(maxlen=REMEMBERED)
        self.foreign = 0
        self.holding_since_s = None

    def sent(self, voltage) -> None:
        self.own.append(tuple(float(v) for v in voltage))

    def heard(self, data) -> None:
        command = tuple(float(v) for v in data)
        if command not in self.own:
            self.foreign += 1

    @property
    def taken(self) -> bool:
        return self.foreign >= TAKE_OVER_COMMANDS

    def hold_from(self, now_s: float) -> None:
        if self.holding_since_s is None:
            self.holding_since_s = now_s

    def expired(self, now_s: float, timeout_s: float) -> bool:
        """The hold has lasted ``timeout_s`` (0: never) with no other node."""
        return (timeout_s > 0.0 and self.holding_since_s is not None
                and now_s - self.holding_since_s >= timeout_s)


def holding(q) -> Excitation:
    """Stay at ``q``: the run samples past its end as its end."""
    return Excitation([Part('holding for a controller', (Hold(q, 1.0),))])


def lowering(arm: ArmConfig, start, rest) -> Excitation:
    """A rest-to-rest move from ``start`` onto ``rest``, then a hold there; ValueError when
    the straight way crosses forbidden space."""
    start, rest = np.asarray(start, float), np.asarray(rest, float)
    if not ForbiddenSpace(arm).segment_is_free(start, rest, 0.001745):
        raise ValueError(f'the straight move from {np.round(start, 3).tolist()} rad to the rest '
                         f'{np.round(rest, 3).tolist()} rad crosses forbidden space')
    distance = float(np.max(np.abs(rest - start)))
    duration = max(1.0, 1.875 * distance / APPROACH_SPEED_RAD_S)
    return Excitation([Part('lowering onto the rest', (Quintic(start, rest, duration),
                                                       Hold(rest, REST_SETTLE_S)))])


def degrees(q) -> str:
    return '[' + ', '.join(f'{math.degrees(v):.1f}' for v in q) + '] deg'


def holding_said(where, timeout_s: float, rest) -> str:
    if timeout_s > 0.0:
        return (f'holding the arm at {degrees(where)} until another node commands it, for '
                f'at most {timeout_s:g} s, then lowering it onto the rest at {degrees(rest)}')
    return (f'holding the arm at {degrees(where)} until another node commands it: start the '
            'controller now (stopping sysid first leaves the arm at 0 V)')
