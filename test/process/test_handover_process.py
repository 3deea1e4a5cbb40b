"""A controller that stops (SIGINT) or dies (SIGKILL), holding or mid-move, leaves the arm
held above the floor (its last profile ends at rest with its holding volts, and the robot
plays it to its end); a controller started again takes the arm over without a drop.

Where the arm went is read from the sim's true state, which the controller never sees."""

import signal
import time

from arm_rig import assert_never_forbidden, DEG
import numpy as np
import pytest

HELD_S = 4.0                    # watched after the controller is gone
STILL_RAD_S = 0.05              # held: every true speed below this over the last second
SPREAD_RAD = 0.5 * DEG          # and every true angle within this of the last second's mean
TAKEOVER_RAD = 3.0 * DEG        # a new controller holds the arm within this of where it was
MOVE_GOAL = (-1.0, 1.0)         # from the start, a long move over the top
MOVING_S = 0.4                  # into the move when the controller goes


def held_still(rig, since_s: float) -> tuple[float, float]:
    """(worst speed, worst spread) of the true state over the last second since ``since_s``."""
    recent = [m for t, m in rig.truth if t >= since_s][-50:]
    q = np.array([m.position for m in recent])
    qd = np.array([m.velocity for m in recent])
    return float(np.max(np.abs(qd))), float(np.max(np.abs(q - q.mean(axis=0))))


@pytest.mark.parametrize('moving', [False, True], ids=['holding', 'mid_move'])
@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGKILL], ids=['stopped', 'killed'])
def test_a_controller_gone_leaves_the_arm_held_and_a_new_one_takes_it(rig, signum, moving):
    rig.reset_sim()
    if moving:
        sent = time.monotonic()
        rig.send(*MOVE_GOAL)
        assert rig.wait_state('tracking', 10.0, since_s=sent), rig.event_log(sent)
        rig.spin_for(MOVING_S)
        assert np.max(np.abs(rig.truth.last().velocity)) > 0.2      # it is moving
    else:
        assert rig.wait_still()
    gone = time.monotonic()
    if signum == signal.SIGINT:
        assert rig.processes['controller'].stop() == 0
    else:
        rig.kill('controller')
    rig.spin_for(HELD_S)
    assert_never_forbidden(rig, gone)
    speed, spread = held_still(rig, gone)
    assert speed < STILL_RAD_S and spread < SPREAD_RAD, (speed, np.degrees(spread))
    held = rig.true_q()

    restarted = time.monotonic()
    rig.start('controller')
    assert rig.wait_state('waiting', 40.0, since_s=restarted), rig.output('controller')
    rig.spin_for(1.0)
    assert_never_forbidden(rig, restarted)
    worst = max(np.max(np.abs(np.array(m.position) - held))
                for m in rig.truth.messages(restarted))
    print(f'{signal.Signals(signum).name} {"mid-move" if moving else "holding"}: held within '
          f'{np.degrees(spread):.2f} deg at {speed:.3f} rad/s; the new controller within '
          f'{np.degrees(worst):.2f} deg')
    assert worst < TAKEOVER_RAD
