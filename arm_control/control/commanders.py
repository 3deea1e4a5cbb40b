"""Which controller keeps the arm when two command it: the one that took it first.

Two commanders on ``voltage_command`` fight: each command undoes the other's, at the rate
they come, from two estimates. Both stopping is no better (0 V drops the arm; silence
leaves a profile playing that nobody corrects). So each controller claims the arm on
``voltage_command_claim`` (std_msgs/Header, transient local): ``stamp`` = the wall time it
became ready to command (its first reading), ``frame_id`` = a token of its own process. It
says its claim again every ``CLAIM_EVERY_S``; a claim not heard for ``CLAIM_STALE_S`` is
gone (its node stopped, or was killed without a goodbye).

The rule, the same in every controller: of the live claims, the earliest (``since_s``, then
the token, so two alike still order) keeps the arm; every other one yields -- it sends
nothing, answers goals and services that it does not command, and when every earlier claim
has gone, takes the arm where it is (as a controller started then would). Two controllers
that see each other therefore never both stop, nor both command for longer than it takes
one's claim to reach the other. A publisher that claims nothing (a script, a rogue) cannot
be stopped from here: it is said, and the controller keeps holding the arm.
"""

from dataclasses import dataclass
import math
from typing import Optional

# A controller says its claim this often (wall s) ...
CLAIM_EVERY_S = 0.5
# ... and a claim not heard again for this long (wall s) is gone. Four missed in a row: a
# loaded machine delays a timer by a period, not by two seconds.
CLAIM_STALE_S = 2.0


@dataclass(frozen=True, order=True)
class Claim:
    """A controller's claim to the arm; claims order as the rule does."""

    since_s: float          # wall time it became ready to command the arm
    token: str              # its process's own


class Commanders:
    """The claims this controller has heard, and whether it keeps the arm or yields.

    ``ready(wall_s)`` once it could command; ``heard(claim, wall_s)`` for each claim that
    comes (its own too: ignored); ``yields(wall_s)`` before each command."""

    def __init__(self, token: str):
        self.token = token
        self.mine: Optional[Claim] = None
        self.rivals: dict = {}          # token -> (Claim, wall s last heard)

    def ready(self, wall_s: float) -> Claim:
        if self.mine is None:
            self.mine = Claim(float(wall_s), self.token)
        return self.mine

    def heard(self, claim: Claim, wall_s: float) -> None:
        if claim.token != self.token and math.isfinite(claim.since_s):
            self.rivals[claim.token] = (claim, float(wall_s))

    def live(self, wall_s: float) -> list:
        """The rivals' claims heard within ``CLAIM_STALE_S``, earliest first; the others are
        forgotten."""
        self.rivals = {token: (claim, heard_s) for token, (claim, heard_s)
                       in self.rivals.items() if wall_s - heard_s <= CLAIM_STALE_S}
        return sorted(claim for claim, _ in self.rivals.values())

    def owner(self, wall_s: float) -> Optional[Claim]:
        """The claim that keeps the arm: the earliest live one, this controller's included."""
        claims = self.live(wall_s) + ([self.mine] if self.mine is not None else [])
        return min(claims, default=None)

    def yields(self, wall_s: float) -> bool:
        """Another live claim comes before this controller's (or it has none yet)."""
        owner = self.owner(wall_s)
        return owner is not None and owner != self.mine
