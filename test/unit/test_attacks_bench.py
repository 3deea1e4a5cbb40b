"""What the attack bench (bench/attack_rig.py) reads from what it hears: known answers.

- the lowest point of either link, for configurations whose answer is plain geometry;
- the loop period from arrival times, a silence at the end of the window counted;
- the lowest point while commanding leaves out an e-stopped arm and an arm whose last
  command is older than the sim's command timeout (the sim applies 0 V then);
- which controller events answer a goal;
- the busy loops stop by themselves.
"""

import math
from pathlib import Path
import sys
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'bench'))

import attack_rig  # noqa: E402
import busy  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

UPPER_M, FORE_M = attack_rig.ARM.shoulder.length_m, attack_rig.ARM.elbow.length_m
TIMEOUT_S = attack_rig.SIM.command_timeout_s


class NoNode:
    """Stands in for the probe's node: the listener's subscriptions go nowhere."""

    def create_subscription(self, *args):
        pass


@pytest.mark.parametrize('shoulder, elbow, lowest_m', [
    (math.pi / 2, -math.pi / 2, UPPER_M),                  # the start: forearm level at 1 m
    (math.pi / 2, 0.0, UPPER_M),                           # straight up: the elbow is lowest
    (0.0, 0.0, 0.0),                                       # straight out along the floor
    (0.0, -math.pi / 2, -FORE_M),                          # forearm hanging into the floor
    (-math.pi / 2, 0.0, -UPPER_M - FORE_M),                # straight down
])
def test_lowest_point_of_either_link(shoulder, elbow, lowest_m):
    assert attack_rig.y_lowest_m(shoulder, elbow) == pytest.approx(lowest_m, abs=1e-12)


def test_period_counts_the_silence_at_the_end():
    arrivals = list(np.arange(0.0, 2.001, 0.02)) + [2.15]    # a 150 ms gap, then silence
    p50, p99, worst, count = attack_rig.period_ms(arrivals, 0.0, 3.0)
    assert p50 == pytest.approx(20.0)
    assert worst == pytest.approx(850.0)                   # 2.15 s to the window's end
    assert count == len(arrivals)
    assert attack_rig.period_ms(arrivals, 0.0, 2.15)[2] == pytest.approx(150.0)


def test_lowest_point_while_commanding_leaves_out_estopped_and_stale_commands():
    heard = attack_rig.Listener(NoNode())
    heard.states = [(0.0, 'holding'), (2.0, 'estopped'), (3.0, 'holding')]
    heard.voltage_s = list(np.arange(0.0, 4.0, 0.02))
    del heard.voltage_s[200 - 50:200 - 20]                  # no command from 3.0 s to 3.6 s
    level = (math.pi / 2, -math.pi / 2)                      # 1000 mm
    heard.truth = [(t, *level) for t in np.arange(0.0, 4.0, 0.02)]
    heard.truth[50] = (1.0, 0.0, 0.0)                        # 0 mm while holding: counted
    heard.truth[125] = (2.5, 0.0, -math.pi / 2)              # e-stopped: overall only
    stale = 3.0 + TIMEOUT_S + 0.05
    heard.truth.append((stale, -math.pi / 2, 0.0))           # no fresh command: overall only
    heard.truth.sort()
    commanding, overall, where = attack_rig.lowest_points_mm(heard, 0.0, 4.0)
    assert commanding == pytest.approx(0.0, abs=1e-9)
    assert where == (1.0, 'holding')
    assert overall == pytest.approx(-1000.0 * (UPPER_M + FORE_M))


def test_events_that_answer_a_goal():
    heard = attack_rig.Listener(NoNode())
    for text in ['goal_queued: goal (1.100, 0.900) m queued (1 waiting)',
                 "goal_accepted: goal preset 'mid_score' accepted: next",
                 'goal_rejected (wrong frame): goal rejected: goal (1.0, 1.0) m is in frame map',
                 "goal_rejected (no such preset): preset 'nope' rejected: no such preset",
                 'goals_rejected: 25 more goals rejected in the last 1.0 s (25 the queue full)',
                 'goal_failed: goal (1.0, 1.0) m failed: the planner did not answer',
                 'goal_reached: reached (1.100, 0.900) m 0.35 s after starting it',
                 'cancelled: cancelled: 3 goals dropped; holding']:
        heard.on_event(attack_rig.String(data=text), {'received_timestamp': 10**9})
    assert [kind for _, kind, _, _ in heard.events][:4] == \
        ['goal_queued', 'goal_accepted', 'goal_rejected', 'goal_rejected']
    assert heard.answers(0.0) == 4 + 25


def test_busy_loops_stop_by_themselves():
    loops = busy.start(count=1, seconds=0.3)
    began = time.monotonic()
    try:
        assert loops[0].wait(timeout=20.0) == 0
        assert time.monotonic() - began >= 0.3
    finally:
        busy.stop(loops)
