"""The ``arm`` tool as a user runs it: a separate process talking to the running nodes."""

import math
from pathlib import Path
import subprocess

import pytest
from ros_harness import install_prefix, ros_environment
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from arm_control.nodes.arm_cli import DONE, NO_ANSWER, REFUSED

GOAL_M = (1.1, 0.9)
LINKS_M = (1.0, 0.8)          # arm.yaml's upper arm and forearm


def arm(domain: int, *args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess:
    executable = install_prefix() / 'lib' / 'arm_control' / 'arm'
    return subprocess.run([str(executable), '--timeout', '45', *args], capture_output=True,
                          text=True, env=ros_environment(domain), timeout=timeout_s)


def tool_m(position) -> tuple[float, float]:
    shoulder, elbow = position
    return (LINKS_M[0] * math.cos(shoulder) + LINKS_M[1] * math.cos(shoulder + elbow),
            LINKS_M[0] * math.sin(shoulder) + LINKS_M[1] * math.sin(shoulder + elbow))


def test_a_goal_a_bad_goal_an_estop_and_the_state(launch, probe, domain):
    for name in ('sim', 'planner', 'controller'):
        launch(name)
    states = probe.collect(String, 'arm_state', 10)
    readings = probe.collect(JointState, 'joint_states')

    reached = arm(domain, 'goal', *map(str, GOAL_M), '--reach')
    assert reached.returncode == DONE, reached.stdout + reached.stderr
    readings.clear()              # the probe did not spin while the tool ran: what it hears
    probe.spin_for(1.0)           # first was queued before; a second of readings ends now
    x, y = tool_m(readings[-1].position)
    assert math.hypot(x - GOAL_M[0], y - GOAL_M[1]) < 0.02

    assert arm(domain, 'goal', '3.0', '0.0').returncode == REFUSED      # out of reach
    assert arm(domain, 'preset', 'no_such_preset').returncode == REFUSED
    assert arm(domain, 'preset', 'high_score').returncode == DONE

    assert arm(domain, 'estop').returncode == DONE
    assert probe.spin_until(lambda: states and states[-1].data == 'estopped', 10.0)
    shown = arm(domain, 'state')
    assert shown.returncode == DONE and 'state: estopped' in shown.stdout.splitlines()
    assert arm(domain, 'goal', *map(str, GOAL_M)).returncode == REFUSED  # until reset
    assert arm(domain, 'reset').returncode == DONE


def test_with_no_arm_it_says_so_and_exits(domain):
    executable = install_prefix() / 'lib' / 'arm_control' / 'arm'
    result = subprocess.run([str(executable), '--timeout', '1', 'goal', '1.1', '0.9'],
                            capture_output=True, text=True, env=ros_environment(domain),
                            timeout=30)
    assert result.returncode == NO_ANSWER


def test_scripts_arm_runs_the_same_tool_without_the_ros2_cli(domain):
    """From the two-command set-up (its .venv and install/), with no arm running."""
    root = Path(__file__).resolve().parents[2]
    if not (root / '.venv' / 'bin' / 'python').exists() or not (root / 'install').is_dir():
        pytest.skip('the two-command set-up (scripts/setup.sh) has not run in this checkout')
    result = subprocess.run([str(root / 'scripts' / 'arm'), '--timeout', '1', 'state'],
                            capture_output=True, text=True, env=ros_environment(domain),
                            timeout=60)
    assert result.returncode == NO_ANSWER, result.stdout + result.stderr


def test_the_command_line_as_a_user_types_it():
    from arm_control.nodes.arm_cli import DEFAULT_TIMEOUT_S, parse
    goal = parse(['goal', '-1.0', '1.0', '--reach'])
    assert (goal.command, goal.x, goal.y, goal.reach, goal.timeout) == \
        ('goal', -1.0, 1.0, True, DEFAULT_TIMEOUT_S)
    assert parse(['--timeout', '3', 'state']).timeout == parse(['state', '--timeout', '3']).timeout
    assert parse(['preset', 'high_score']).name == 'high_score'
    with pytest.raises(SystemExit):
        parse(['goal', '1.0'])                          # a point needs both coordinates
