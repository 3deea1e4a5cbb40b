"""What the viewer and the markers node keep from messages, and the MarkerArray they make."""

import math
from pathlib import Path

import numpy as np
import pytest
from visualization_msgs.msg import Marker

from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.parameters import ParameterError, read_parameter_file
from arm_control.visual.markers import MarkerBuilder
from arm_control.visual.scene import state_colour
from arm_control.visual.viewer_model import STALE_AFTER_S, ViewerConfig, ViewerModel


@pytest.fixture
def model(arm):
    return ViewerModel(arm, goal_reached_m=0.03)


@pytest.fixture(scope='module')
def kinematics(arm):
    return TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)


def move_tool_to(model, kinematics, x, y, now_s=0.0):
    q = next(q for q in kinematics.inverse(x, y) if model.space.is_free(q))
    assert model.on_joint_state(q, now_s) is None


def test_goals_queue_in_order_and_leave_when_the_tool_reaches_the_first(model, kinematics):
    for x, y in ((1.2, 0.5), (-1.0, 1.0), (0.5, 1.2)):
        assert model.on_goal(x, y) is None
    move_tool_to(model, kinematics, -1.0, 1.0)          # the second goal: not its turn
    assert model.goals == [(1.2, 0.5), (-1.0, 1.0), (0.5, 1.2)]
    move_tool_to(model, kinematics, 1.2 + 0.04, 0.5)    # 4 cm away: not yet
    assert len(model.goals) == 3
    move_tool_to(model, kinematics, 1.2 + 0.02, 0.5)    # 2 cm: reached
    assert model.goals == [(-1.0, 1.0), (0.5, 1.2)]


def test_goals_the_controller_would_reject_are_not_queued(model):
    assert 'not finite' in model.on_goal(math.nan, 1.0)
    assert 'frame' in model.on_goal(1.0, 1.0, frame_id='map')
    assert 'z = ' in model.on_goal(1.0, 1.0, z=0.2)
    assert 'no allowed configuration' in model.on_goal(1.0, -0.2)     # under the floor
    assert 'no allowed configuration' in model.on_goal(2.0, 1.0)      # out of reach
    assert model.on_goal(1.0, 1.0, frame_id='arm_base') is None
    assert model.goals == [(1.0, 1.0)]


def test_the_queue_empties_when_the_controller_goes_back_to_waiting(model):
    model.on_state('waiting')
    model.on_goal(1.0, 1.0)
    model.on_state('waiting')                       # the latched state, again: no change
    assert model.goals == [(1.0, 1.0)]
    model.on_state('planning')
    model.on_state('error')
    assert model.goals == [(1.0, 1.0)]
    model.on_state('waiting')
    assert model.goals == []


def test_bad_joint_states_are_refused_and_the_last_good_one_kept(model):
    assert model.on_joint_state([0.5, 0.2], 1.0) is None
    assert model.on_joint_state([math.nan, 0.0], 2.0) is not None
    assert model.on_joint_state([0.1], 2.0) is not None
    assert model.joint_rad == (0.5, 0.2)
    assert model.scene(1.0 + STALE_AFTER_S / 2).note == ''
    assert model.scene(3.0).note == 'no joint_states for 2.0 s'


def test_the_path_arrives_as_tool_poses_and_is_kept_as_configurations(model, kinematics):
    path = [(1.5708, -1.5708), (2.5, -0.5), (3.3, 0.6)]
    assert model.on_path([kinematics.tool_pose(q) for q in path]) is None
    assert np.allclose(model.scene(0.0).path_rad, path, atol=1e-9)
    assert model.on_path([(1.0, math.inf, 0.0)]) is not None
    assert len(model.path_rad) == 3                 # the bad path did not replace it
    assert model.on_path([]) is None and model.path_rad == ()


def test_the_path_shown_is_the_arms_last_move_not_the_planning_ahead(model, kinematics):
    """Holding, the controller asks for the paths between presets and the planner publishes
    them; the picture keeps the path of the move just made."""
    move = [(2.5, -0.5), (2.0, -1.0), (1.5708, -1.5708)]
    ahead = [(0.3, 2.4), (1.0, 1.0), (2.8, -1.2)]
    model.on_joint_state(move[0], 0.0)
    model.on_state('planning')
    model.on_path([kinematics.tool_pose(q) for q in move])
    model.on_state('tracking')
    model.on_joint_state(move[-1], 1.0)
    model.on_state('holding')
    model.on_path([kinematics.tool_pose(q) for q in ahead])
    assert np.allclose(model.scene(1.0).path_rad, move, atol=1e-9)
    # The next goal's path may come before its state does: taken when it starts at the arm.
    onward = [move[-1], (2.0, -1.2)]
    model.on_path([kinematics.tool_pose(q) for q in onward])
    model.on_state('planning')
    assert np.allclose(model.scene(1.1).path_rad, onward, atol=1e-9)


def test_viewer_parameters_from_the_file():
    params = read_parameter_file(Path(__file__).resolve().parents[2] / 'config' / 'arm.yaml',
                                 'viewer')
    viewer = ViewerConfig.from_parameters(params)
    assert viewer.rate_hz > 0 and viewer.png_rate_hz > 0 and viewer.headless is False
    with pytest.raises(ParameterError, match="'rate_hz'"):
        ViewerConfig.from_parameters({**params, 'rate_hz': 0.0})
    with pytest.raises(ParameterError, match="'headless'"):
        ViewerConfig.from_parameters({**params, 'headless': 'yes'})


def test_markers_put_the_links_where_forward_kinematics_does(arm, kinematics):
    builder = MarkerBuilder(arm)
    model = ViewerModel(arm)
    q = (1.1, -0.7)
    model.on_joint_state(q, 0.0)
    model.on_state('tracking')
    model.on_goal(1.2, 0.5)
    markers = {(m.ns, m.id): m for m in builder.build(model.scene(0.0)).markers}
    links = markers[('arm', 0)]
    assert links.header.frame_id == 'arm_base' and links.type == Marker.LINE_STRIP
    expected = [(0.0, 0.0), kinematics.elbow_point(q), kinematics.forward(q)]
    assert np.allclose([(p.x, p.y, p.z) for p in links.points],
                       [(x, y, 0.0) for x, y in expected])
    r, g, b = (int(state_colour('tracking')[i:i + 2], 16) / 255 for i in (1, 3, 5))
    assert (links.color.r, links.color.g, links.color.b, links.color.a) == pytest.approx(
        (r, g, b, 1.0))
    assert [(p.x, p.y) for p in markers[('goals', 0)].points] == [(1.2, 0.5)]
    assert markers[('path', 0)].action == Marker.DELETE            # no path yet
    floor = markers[('forbidden', 0)]
    assert floor.type == Marker.CUBE and floor.text == 'floor'
    assert floor.pose.position.y + floor.scale.y / 2 == pytest.approx(0.0)   # its top: y = 0
    outer = markers[('reach', 1)]
    assert max(math.hypot(p.x, p.y) for p in outer.points) == pytest.approx(1.8)
