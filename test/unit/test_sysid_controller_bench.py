"""What bench/bench_sysid_controller.py reports for a move: known answers on the sysid demo
arm with its true file (in-process, deterministic).

- a goal the arm cannot hold within its current limit is refused, never a time;
- a move is timed from an arm at rest: in one process the arm starts at 0 V and drops until
  the first command acts, and near full extension it is still coming back 0.5 s later.
"""

import math
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'bench'))

import bench_sysid_controller as bench  # noqa: E402
from bench_trajectory import SUITE  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from robot_clock import start_configuration  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.model.dynamics import ArmDynamics  # noqa: E402
from arm_control.model.electrical import PowerSupply  # noqa: E402
from arm_control.model.kinematics import TwoLinkKinematics  # noqa: E402
from arm_control.planning.planner import Planner  # noqa: E402

FAR_LOW_BACK = SUITE[11]             # low front -> far low back
FULL_EXTENSION_LOW = SUITE[3]        # floor -> full extension low
SHORT_HOP = SUITE[5]                 # short hop, floor


@pytest.fixture(scope='module')
def demo():
    return config.ArmConfig.from_parameters(bench.layered(
        bench.CONFIG / 'arm.yaml', bench.CONFIG / 'sysid_demo_arm.yaml'))


def run(demo, controller_config, move, seed):
    _, start_xy, goal_xy = move
    planner = Planner(demo, config.load('planner')[1])
    return bench.run_move(demo, demo, controller_config, planner,
                          start_configuration(demo, start_xy), goal_xy, seed)


def holding_v(demo, goal_xy) -> float:
    """The shoulder's volts holding the arm still at ``goal_xy``, the easier elbow branch."""
    dynamics = ArmDynamics(demo)
    kinematics = TwoLinkKinematics(demo.shoulder.length_m, demo.elbow.length_m)
    return min(abs(dynamics.voltage_for(q, (0.0, 0.0), (0.0, 0.0))[0])
               for q in kinematics.inverse(*goal_xy))


def test_goals_beyond_the_current_limit_are_refused_not_timed(demo, controller_config):
    """Holding the demo arm out at full extension low takes more volts than the shoulder's
    current limit gives (I_limit·R); at the far low back, more than it gives less the
    feedback reserve, which the timing keeps back braking into the goal. Both are refused
    with the true file: no time."""
    window_v = PowerSupply(demo, ArmDynamics(demo).motors).current_window_v[0]
    assert holding_v(demo, FULL_EXTENSION_LOW[2]) > window_v
    assert holding_v(demo, FAR_LOW_BACK[2]) > \
        window_v - controller_config.feedback_voltage_reserve
    for k, move in ((3, FULL_EXTENSION_LOW), (11, FAR_LOW_BACK)):
        result = run(demo, controller_config, move, k)
        assert result.refused and math.isnan(result.time_s)


def test_a_move_is_timed_from_an_arm_at_rest(demo, controller_config):
    """At the far low back's start the arm has come to rest before the goal is given, and
    a move the arm can do is timed from then: above zero, and settled."""
    move = run(demo, controller_config, FAR_LOW_BACK, 11)
    assert move.start_rest_deg < bench.AT_REST_DEG
    hop = run(demo, controller_config, SHORT_HOP, 5)
    assert not hop.refused and 0.0 < hop.time_s < 1.0
    assert np.isfinite(hop.final_deg) and hop.final_deg < 0.2
