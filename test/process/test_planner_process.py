"""The installed ``planner`` executable, as its own process, asked for plans over DDS."""

import math
import os
from pathlib import Path

from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import OccupancyGrid, Path as PathMsg
from nav_msgs.srv import GetPlan
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from arm_control import config
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.world import ForbiddenSpace
from arm_control.planning.planner import Planner
from arm_control.planning.poses import poses_from_waypoints, waypoints_from_poses

FRC_FILE = Path(__file__).resolve().parents[2] / 'config' / 'frc_robot.yaml'
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
START_Q = (math.pi / 2, -math.pi / 2)


@pytest.fixture(scope='module')
def frc():
    arm, planner_config = config.load('planner', FRC_FILE)
    return arm, planner_config, ForbiddenSpace(arm)


def pose(x, y, yaw=0.0, frame_id='arm_base'):
    msg = PoseStamped()
    msg.header.frame_id = frame_id
    msg.pose.position.x, msg.pose.position.y = float(x), float(y)
    msg.pose.orientation.z, msg.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return msg


def request_from(kinematics, start_q, goal_xy, **goal_fields):
    request = GetPlan.Request()
    request.start = pose(*kinematics.tool_pose(start_q))
    request.goal = pose(*goal_xy, **goal_fields)
    return request


def to_tuples(path_msg):
    return [(p.pose.position.x, p.pose.position.y,
             2.0 * math.atan2(p.pose.orientation.z, p.pose.orientation.w))
            for p in path_msg.poses]


def test_plans_over_the_top_and_latches_the_path_and_the_map(launch, probe, frc):
    arm, planner_config, forbidden = frc
    planner = launch('planner', '--params-file', str(FRC_FILE))
    pure = Planner(arm, planner_config)
    kinematics = pure.kinematics
    goals = {name: (x, y) for name, x, y in arm.presets}
    high = pure.plan(START_Q, goals['high_score']).waypoints_rad[-1]

    response = probe.call(GetPlan, '/plan_path',
                          request_from(kinematics, high, goals['back_score']), timeout_s=30.0,
                          idempotent=True)
    assert response.plan.header.frame_id == 'arm_base'
    poses = to_tuples(response.plan)
    assert len(poses) >= 3                                 # it cannot go straight
    waypoints = waypoints_from_poses(kinematics, poses, high, forbidden)
    np.testing.assert_allclose(waypoints[0], high, atol=1e-9)
    np.testing.assert_allclose(kinematics.forward(waypoints[-1]), goals['back_score'],
                               atol=1e-6)
    assert forbidden.path_is_free(waypoints, math.radians(0.1))
    # The node's plan is as short as the pure planner's, to the same end. (Not the same
    # path: with joint travel as the cost many paths tie, and which one the search meets
    # first depends on the edges checked before, such as by the preset trees the node
    # builds while idle.)
    expected = pure.plan(high, goals['back_score']).waypoints_rad
    np.testing.assert_allclose(np.abs(np.diff(waypoints, axis=0)).sum(),
                               np.abs(np.diff(expected, axis=0)).sum(), atol=1e-5)
    np.testing.assert_allclose(poses[-1], poses_from_waypoints(kinematics, expected)[-1],
                               atol=1e-9)

    # Subscribers that arrive late still get the last plan and the map (transient local).
    paths = probe.collect(PathMsg, '/planned_path', LATCHED)
    maps = probe.collect(OccupancyGrid, '/cspace_map', LATCHED)
    assert probe.spin_until(lambda: paths and maps, 15.0), 'latched topics did not arrive'
    np.testing.assert_allclose(to_tuples(paths[-1]), poses, atol=1e-12)
    grid_map = maps[-1]
    grid = pure.grid
    assert (grid_map.info.width, grid_map.info.height) == \
        (grid.shoulder.count, grid.elbow.count)
    assert grid_map.info.resolution == pytest.approx(planner_config.grid_resolution_rad)
    data = np.array(grid_map.data).reshape(grid_map.info.height, grid_map.info.width)
    assert set(np.unique(data)) == {0, 100}

    def cell_value(q):
        i = int((q[0] - grid_map.info.origin.position.x) / grid_map.info.resolution)
        j = int((q[1] - grid_map.info.origin.position.y) / grid_map.info.resolution)
        return data[j, i]                                  # row = elbow, column = shoulder

    assert cell_value(grid.configurations[grid.node_of(100, 150)]) == \
        (0 if grid.free[100, 150] else 100)
    assert cell_value(np.radians([90.0, -90.0])) == 0      # upper arm up, forearm level
    assert cell_value(np.radians([90.0, 60.0])) == 100     # forearm through the height limit
    assert planner.alive()


def test_once_prepared_every_thread_of_the_planner_runs_at_its_priority(launch, probe):
    """A goal must not wait behind busy processes for its plan: once the planner has its
    preset answers, all its threads (DDS's that receive a request too) are SCHED_FIFO at
    ``realtime_priority``; where the system refuses, the node says how to allow it."""
    _, planner_config = config.load('planner')
    planner = launch('planner')
    pid = planner.process.pid

    def policies():
        found = set()
        for task in Path(f'/proc/{pid}/task').iterdir():
            try:
                found.add((os.sched_getscheduler(int(task.name)),
                           os.sched_getparam(int(task.name)).sched_priority))
            except ProcessLookupError:                      # a thread that ended meanwhile
                pass
        return found
    fifo = {(os.SCHED_FIFO, planner_config.realtime_priority)}
    assert probe.spin_until(lambda: policies() == fifo
                            or 'real-time priority' in planner.output(), 30.0), policies()
    if 'real-time priority' in planner.output():
        assert 'rtprio' in planner.output()                 # how to allow it
    else:
        assert policies() == fifo


def test_bad_requests_get_an_empty_path_and_the_node_lives(launch, probe, frc):
    arm = frc[0]
    planner = launch('planner', '--params-file', str(FRC_FILE))
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    good = request_from(kinematics, START_Q, (1.1, 0.25))

    wrong_frame = request_from(kinematics, START_Q, (1.1, 0.25), frame_id='map')
    not_a_number = request_from(kinematics, START_Q, (math.nan, 0.25))
    off_plane = request_from(kinematics, START_Q, (1.1, 0.25))
    off_plane.goal.pose.position.z = 0.2
    not_the_arm = request_from(kinematics, START_Q, (1.1, 0.25))
    not_the_arm.start.pose.position.x += 0.3               # no configuration has this pose
    out_of_reach = request_from(kinematics, START_Q, (3.0, 0.0))
    inside_robot = request_from(kinematics, START_Q, (0.60, -0.50))
    for bad in (wrong_frame, not_a_number, off_plane, not_the_arm, out_of_reach,
                inside_robot):
        response = probe.call(GetPlan, '/plan_path', bad, timeout_s=30.0, idempotent=True)
        assert len(response.plan.poses) == 0
        assert planner.alive()

    response = probe.call(GetPlan, '/plan_path', good, timeout_s=30.0, idempotent=True)
    assert len(response.plan.poses) >= 2
    output = planner.output()
    assert "frame 'map'" in output and 'rejected a plan_path request' in output
    assert 'out of reach' in output and '"intake"' in output
