"""The viewer's picture, rendered headless and looked at pixel by pixel."""

import math

from matplotlib import image
import numpy as np
import pytest

from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.world import ForbiddenSpace
from arm_control.visual import scene as scene_module
from arm_control.visual.scene import (cspace_image, densify, GOAL_COLOUR, PATH_COLOUR,
                                      path_configurations, REACH_COLOUR, reachable_free, Scene,
                                      state_colour, workspace_extent)
from arm_control.visual.scene_view import SceneView

SIZE_PX = (800, 450)


@pytest.fixture(scope='module')
def view(arm):
    return SceneView(arm, size_px=SIZE_PX)


@pytest.fixture(scope='module')
def kinematics(arm):
    return TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)


def rgb(colour):
    return np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)])


def colour_near(picture, pixel, colour, radius=2, tolerance=40) -> bool:
    """Whether some pixel within ``radius`` of ``pixel`` is within ``tolerance`` of colour."""
    column, row = pixel
    patch = picture[row - radius:row + radius + 1, column - radius:column + radius + 1]
    return bool(np.any(np.max(np.abs(patch.astype(int) - rgb(colour)), axis=-1) <= tolerance))


def link_points(kinematics, q, fractions=(0.3, 0.5, 0.7)):
    elbow = np.array(kinematics.elbow_point(q))
    tool = np.array(kinematics.forward(q))
    return ([f * elbow for f in fractions] + [elbow + f * (tool - elbow) for f in fractions])


# Points over the workspace, below the state's name (drawn in the arm's colour, top right).
PROBES = [np.array((x, y)) for x in np.arange(-1.6, 1.61, 0.2) for y in np.arange(0.1, 1.41, 0.2)]


def distance_to_segment(point, start, end) -> float:
    along = np.clip(np.dot(point - start, end - start) / np.dot(end - start, end - start), 0, 1)
    return float(np.linalg.norm(point - (start + along * (end - start))))


def test_picture_has_the_requested_size(view, tmp_path):
    frame = Scene(joint_rad=(1.5708, -1.5708), state='waiting')
    assert view.render_rgb(frame).shape == (SIZE_PX[1], SIZE_PX[0], 3)
    view.render_png(frame, tmp_path / 'frame.png')
    assert image.imread(tmp_path / 'frame.png').shape[:2] == (SIZE_PX[1], SIZE_PX[0])


def test_natural_size_fits_the_workspace_to_scale(arm):
    width_px, height_px = SceneView.natural_size_px(workspace_extent(arm))
    assert width_px == 1000
    # 4.0 m wide by 2.2 m tall, drawn 620 px wide, plus 80 px of margins
    assert height_px == pytest.approx(620 * 2.2 / 4.0 + 80, abs=1)


def test_arm_coloured_pixels_lie_where_forward_kinematics_puts_the_links(view, kinematics):
    rng = np.random.default_rng(7)
    space = ForbiddenSpace(view.arm)
    colour = state_colour('tracking')
    checked = 0
    while checked < 6:
        q = (rng.uniform(0.0, math.pi), rng.uniform(-2.8, 2.8))
        if not space.is_free(q):
            continue
        picture = view.render_rgb(Scene(joint_rad=q, state='tracking'))
        for point in link_points(kinematics, q):
            assert colour_near(picture, view.pixel_of(*point), colour), (q, point)
        # ... and nowhere else: probe points more than 12 cm from both links
        elbow, tool = np.array(kinematics.elbow_point(q)), np.array(kinematics.forward(q))
        for point in PROBES:
            if min(distance_to_segment(point, np.zeros(2), elbow),
                   distance_to_segment(point, elbow, tool)) > 0.12:
                assert not colour_near(picture, view.pixel_of(*point), colour), (q, point)
        checked += 1


def test_the_arm_and_the_state_text_change_colour_with_the_state(view, kinematics):
    q = (1.2, -0.9)
    middle = view.pixel_of(*link_points(kinematics, q, (0.5,))[0])
    seen = {}
    for state in ('tracking', 'E-STOPPED', 'holding', 'waiting'):
        picture = view.render_rgb(Scene(joint_rad=q, state=state))
        colour = state_colour(state)
        assert np.max(np.abs(picture[middle[1], middle[0]].astype(int) - rgb(colour))) <= 3
        # the state's name, top right, in the same colour
        top_right = picture[:SIZE_PX[1] // 4, SIZE_PX[0] // 3:int(SIZE_PX[0] * 0.7)]
        assert np.any(np.max(np.abs(top_right.astype(int) - rgb(colour)), axis=-1) <= 10)
        seen[state] = tuple(picture[middle[1], middle[0]])
    assert len(set(seen.values())) == 4


def test_state_colours_by_name():
    assert state_colour('E-STOPPED') == state_colour('estop') == state_colour('e_stopped')
    assert state_colour('tracking') == state_colour('TRACKING')
    assert state_colour('finished') == state_colour('holding')
    names = ('waiting', 'tracking', 'holding', 'error', 'estopped', 'disabled', 'driver',
             'no_sensors')
    assert len({state_colour(name) for name in names}) == len(names)
    assert state_colour('') == state_colour('something new') == scene_module.UNKNOWN_STATE_COLOUR


def test_forbidden_regions_and_the_reachable_annulus_are_shaded(view):
    picture = view.render_rgb(Scene())
    white = np.array([255, 255, 255])

    def mean_colour(x, y):
        column, row = view.pixel_of(x, y)
        return picture[row - 3:row + 4, column - 3:column + 4].reshape(-1, 3).mean(axis=0)

    floor = mean_colour(1.0, -0.1)
    assert np.all(floor < 215) and np.ptp(floor) < 25          # hatched grey
    reachable = mean_colour(1.0, 0.8)
    assert reachable[1] > reachable[0] + 10 and reachable[1] > reachable[2] + 10   # green
    assert np.all(reachable > 200)                              # ... but light
    beyond_reach = mean_colour(1.75, 1.3)
    assert np.allclose(beyond_reach, white, atol=3)
    # inside the inner circle the links would have to fold past the elbow's limit
    assert np.allclose(mean_colour(0.0, 0.08), white, atol=12)


def test_path_goals_and_ghost_are_drawn(view, kinematics):
    path = ((1.5708, -1.5708), (2.3, -1.2), (2.9, 0.2))
    goals = ((1.2, 0.5), (-1.0, 1.0))
    picture = view.render_rgb(Scene(joint_rad=(0.5, 1.0), state='tracking', path_rad=path,
                                    goals_xy=goals, ghost_xy=(1.0, 1.3)))
    middle = densify(path)[len(densify(path)) // 3]
    assert colour_near(picture, view.pixel_of(*kinematics.forward(middle)), PATH_COLOUR)
    for x, y in goals:
        column, row = view.pixel_of(x, y)
        assert colour_near(picture, (column + 4, row), GOAL_COLOUR, radius=1)
    assert colour_near(picture, view.pixel_of(1.0, 1.3), REACH_COLOUR, radius=1, tolerance=60)

    unreachable = view.render_rgb(Scene(ghost_xy=(1.0, 1.7)))   # 1.97 m away: out of reach
    assert colour_near(unreachable, view.pixel_of(1.0, 1.7), scene_module.BLOCKED_COLOUR,
                       radius=1, tolerance=60)
    assert not colour_near(unreachable, view.pixel_of(1.0, 1.7), REACH_COLOUR, radius=1,
                           tolerance=60)


def test_reachable_free_known_points(arm):
    space = ForbiddenSpace(arm)
    assert reachable_free(space, 0.0, 1.8)            # straight up
    assert reachable_free(space, 0.0, 0.3)            # folded 166 deg, above the floor
    assert not reachable_free(space, 0.0, 0.25)       # would fold 170.4 deg > 170 allowed
    assert not reachable_free(space, 0.0, 0.1)        # inside the inner radius
    assert not reachable_free(space, 1.0, -0.1)       # under the floor
    assert not reachable_free(space, 1.7, 0.9)        # beyond 1.8 m


def test_every_allowed_configuration_puts_the_tool_on_a_reachable_point(arm, kinematics):
    space = ForbiddenSpace(arm)
    rng = np.random.default_rng(3)
    q = np.column_stack([rng.uniform(*space.limits[0], 4000), rng.uniform(*space.limits[1], 4000)])
    q = q[space.is_free(q)]
    tool = np.array([kinematics.forward(c) for c in q])
    assert len(q) > 500
    assert np.all(reachable_free(space, tool[:, 0], tool[:, 1]))


def test_path_configurations_round_trip_over_the_top(arm, kinematics):
    space = ForbiddenSpace(arm)
    path = [(1.5708, -1.5708), (2.6, -0.4), (3.3, 0.5), (3.45, 1.2)]   # shoulder past 180 deg
    poses = [kinematics.tool_pose(q) for q in path]
    assert np.allclose(path_configurations(space, poses), path, atol=1e-9)


def test_densify_keeps_waypoints_and_step():
    path = [(0.0, 0.0), (1.0, -0.5), (1.0, 0.5)]
    dense = densify(path, step_rad=0.1)
    assert np.allclose(dense[0], path[0]) and np.allclose(dense[-1], path[-1])
    assert any(np.allclose(row, path[1]) for row in dense)
    assert np.max(np.abs(np.diff(dense, axis=0))) <= 0.1 + 1e-12


def test_workspace_extent_crops_below_the_floor(arm):
    assert workspace_extent(arm) == pytest.approx((-2.0, 2.0, -0.2, 2.0))


def test_cspace_image_known_cells(arm):
    picture = cspace_image(ForbiddenSpace(arm), math.radians(2.0))

    def occupied(shoulder_deg, elbow_deg):
        col = int((math.radians(shoulder_deg) - picture.shoulder_min_rad) / picture.resolution_rad)
        row = int((math.radians(elbow_deg) - picture.elbow_min_rad) / picture.resolution_rad)
        return picture.occupied[row, col]

    assert not occupied(90.0, -90.0)       # the start: up, forearm level
    assert occupied(-10.0, 0.0)            # straight, pointing into the floor
    assert occupied(170.0, 30.0)           # forearm down through the floor behind
    assert picture.extent_deg[0] == pytest.approx(math.degrees(arm.shoulder.min_angle_rad))
