"""Which of several controllers keeps the arm (control/commanders.py): exactly one of those
that hear each other, the earliest; the others yield until its claim goes."""

import numpy as np

from arm_control.control.commanders import Claim, CLAIM_STALE_S, Commanders


def _hearing_each_other(claims, wall_s):
    """Each controller, ready at its claim's instant, has heard every other's claim."""
    controllers = []
    for claim in claims:
        mine = Commanders(claim.token)
        mine.ready(claim.since_s)
        for other in claims:
            mine.heard(other, wall_s)           # its own too: ignored
        controllers.append(mine)
    return controllers


def test_of_controllers_that_hear_each_other_exactly_the_earliest_keeps_the_arm():
    rng = np.random.default_rng(39)
    for _ in range(200):
        count = int(rng.integers(2, 5))
        # Some ready at the same instant: the token orders them.
        since = rng.choice([100.0, 100.5, 101.0, 103.0], size=count)
        claims = [Claim(float(s), f'host:{int(rng.integers(1, 99999))}:{k}')
                  for k, s in enumerate(since)]
        controllers = _hearing_each_other(claims, 104.0)
        keeping = [c for c in controllers if not c.yields(104.0)]
        assert len(keeping) == 1
        assert keeping[0].mine == min(claims)


def test_the_later_one_yields_until_the_earlier_claim_goes_then_takes_the_arm():
    first, later = Claim(10.0, 'a:1:x'), Claim(20.0, 'b:2:y')
    owner, standby = _hearing_each_other([first, later], 20.0)
    assert not owner.yields(20.0) and standby.yields(20.0)
    for wall_s in np.arange(20.5, 30.0, 0.5):   # both say their claims every half second
        owner.heard(later, wall_s)
        standby.heard(first, wall_s)
        assert not owner.yields(wall_s) and standby.yields(wall_s)
    # The first goes (killed: no goodbye); its last claim was heard at 29.5.
    assert standby.yields(29.5 + CLAIM_STALE_S)
    assert not standby.yields(29.5 + CLAIM_STALE_S + 0.01)
    # Started again, it comes after the one that now has the arm, and yields to it.
    again = Claim(33.0, 'a:3:z')
    restarted, standby_now = _hearing_each_other([again, later], 33.0)
    assert restarted.yields(33.0) and not standby_now.yields(33.0)


def test_a_controller_not_yet_ready_yields_to_one_it_hears_and_keeps_the_arm_alone():
    waiting = Commanders('b:2:y')
    assert not waiting.yields(5.0)              # alone: nothing to yield to
    waiting.heard(Claim(1.0, 'a:1:x'), 5.0)
    assert waiting.yields(5.0)
    alone = Commanders('c:3:z')
    alone.ready(7.0)
    alone.heard(alone.mine, 7.5)
    assert not alone.yields(7.5) and alone.owner(7.5) == alone.mine
