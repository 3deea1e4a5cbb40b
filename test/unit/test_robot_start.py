"""A move on the robot's clock: it starts at the robot's first instant its command reaches,
costs at most that wait (a period, plus the command's way there) over commands applied on
arrival, and a start whose first command came after its instant costs that period, no more."""

import math

import numpy as np
import pytest

from arm_control.control import robot_command
from arm_control.control.robot_loop import RobotLoop
from arm_control.model.profile import Profile

PERIOD_S = 0.02
LAG_S = 0.004                     # RobotLoop's command lag
HOP = ((0.84, -1.68), (1.3, 0.2))  # 'short hop, floor' of the suite: 0.1 s at the limits


def _record(loop) -> list:
    """Every command (arrives ms, command) RobotLoop sends from now, as it is sent."""
    sent, tick = [], loop._tick

    def recorded(now_ms):
        tick(now_ms)
        sent.append(loop.commands[-1])
    loop._tick = recorded
    return sent


def _move(arm, controller_config, planner, phase_ms, robot_loop=True, jitter_ms=0, seed=5):
    """(seconds from the goal until within 1 deg of the rest it came to, for good; the lowest
    point of the move m; the commands sent since the goal)."""
    start, goal = HOP
    loop = RobotLoop(arm, controller_config, planner, start=start, seed=seed,
                     mode='profile' if robot_loop else 'volts', phase_s=phase_ms / 1000.0,
                     robot_loop=robot_loop, lag_jitter_ms=jitter_ms)
    loop.run(0.5)
    goal_s, loop.lowest_m = loop.now_s, math.inf
    sent = _record(loop)
    loop.submit_goal(*goal)
    loop.run(1.5)
    times = np.array([t for t, _ in loop.history])
    q = np.array([s[:2] for _, s in loop.history])
    away = np.flatnonzero(np.any(np.abs(q - q[-1]) > math.radians(1.0), axis=1))
    return times[away[-1] + 1] - goal_s, loop.lowest_m, sent


@pytest.mark.parametrize('phase_ms', [0, 3, 5, 10, 16, 19])
def test_a_move_at_any_phase_costs_at_most_the_wait_for_the_robot_loop(
        arm, controller_config, planner, phase_ms):
    """The goal comes ``phase_ms`` before a robot instant, each command 4 +- 3 ms late (in
    the order sent): the move takes at most a period and the command's way there longer
    than with commands applied on arrival, and stays above the floor."""
    reference_s, _, _ = _move(arm, controller_config, planner, 0, robot_loop=False)
    move_s, lowest_m, _ = _move(arm, controller_config, planner, phase_ms, jitter_ms=3)
    assert move_s <= reference_s + PERIOD_S + LAG_S + 0.003
    assert lowest_m > 0.1


@pytest.mark.parametrize('phase_ms', [2, 3])
def test_a_start_taken_a_robot_loop_late_costs_that_period(
        arm, controller_config, planner, monkeypatch, phase_ms):
    """Aimed at the instant ``phase_ms`` after the goal, the first profile arrives after it
    and is taken a loop later: the move no slower than one aimed at that later instant."""
    safe_s, _, sent = _move(arm, controller_config, planner, phase_ms)
    first = next(c for _, c in sent if isinstance(c, Profile))
    assert first.start_s > 0.5 + phase_ms / 1000.0         # aimed at the later instant
    monkeypatch.setattr(robot_command, 'ARRIVAL_MARGIN_S', -0.003)
    missed_s, lowest_m, sent = _move(arm, controller_config, planner, phase_ms)
    arrives_ms, first = next((a, c) for a, c in sent if isinstance(c, Profile))
    assert arrives_ms > round(1000.0 * first.start_s)      # it came after its instant
    assert missed_s <= safe_s + 0.002
    assert lowest_m > 0.1


def test_commands_arrive_in_the_order_sent_whatever_their_jitter(arm, controller_config):
    loop = RobotLoop(arm, controller_config, start=(0.0, 1.75), seed=3, lag_jitter_ms=8)
    sent = _record(loop)
    for _ in range(50):              # a tick at once each 21 ms: a plan ready (ControlLoop.poke)
        loop.run(0.021)
        loop.poke()
    arrivals = [a for a, _ in sent]
    assert len(arrivals) > 70 and arrivals == sorted(arrivals)
    assert len(set(np.diff(arrivals))) > 3                  # the jitter is there
