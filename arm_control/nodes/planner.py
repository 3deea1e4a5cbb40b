"""The ``planner`` node: collision-free joint-space paths on request.

Serves ``plan_path`` (nav_msgs/GetPlan): ``start`` = the tool pose (x, y, yaw as a rotation
about z) of the configuration to plan from, ``goal`` = the target position (its orientation
is ignored: the planner picks the elbow branch), both in ``arm_base`` (an empty frame_id
means ``arm_base``). The response is a Path of tool poses in ``arm_base``, start to goal;
consecutive poses are joined by straight lines in joint space (turn them back into joint
angles with ``arm_control.planning.planner.waypoints_from_poses``). An empty path means no
plan; the reason is logged.

Publishes ``planned_path`` (Path, latched: the last successful plan), ``cspace_map``
(OccupancyGrid, latched, published once at start) and ``/diagnostics``. In its first second
it builds the shortest-path trees toward every preset's elbow branches (``Planner.prepare``),
so that plans to a preset need no search; then, in the next few, the answers from each
preset's branches to every other preset (``PresetAnswers``), so that a goal from one preset
to another is answered at once; then it proves every cell of joint space its checks look up
(``Planner.prove_cells``), so that a goal into a part no check had been to does not pay for
them.

``cspace_map`` is the configuration space as a map in frame ``cspace`` (set RViz's fixed
frame to it): cell (i, j) = (shoulder cell i, elbow cell j), so x is the shoulder angle and
y the elbow angle, metres standing for radians. ``info.resolution`` = grid_resolution_rad;
``info.origin`` = (shoulder, elbow) of the corner of cell (0, 0), so cell (i, j) is centred
at origin + (i + ½, j + ½) · resolution; ``data[j · width + i]`` = 100 forbidden, 0 free.
The grid spans each joint's travel between its hard stops (see planning/graph.py).
"""

import math
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import OccupancyGrid, Path
from nav_msgs.srv import GetPlan
import numpy as np
from rclpy.node import Node

from arm_control import realtime
from arm_control.config import ArmConfig, FRAME_ID, PlannerConfig
from arm_control.nodes import messages
from arm_control.nodes.common import declare_parameters, LATCHED, run, status
from arm_control.planning.planner import Planner
from arm_control.planning.poses import poses_from_waypoints
from arm_control.plans.cache import PresetAnswers
from arm_control.plans.goals import PLANE_TOLERANCE_M
from arm_control.plans.timer import BranchRanking
from arm_control.text import quote
from arm_control.timing.bus import compile_kernels

CSPACE_FRAME = 'cspace'
POSE_TOLERANCE_M = 0.001          # a start pose must be a pose of this arm within this
PREPARE_PERIOD_S = 0.05           # one preset branch's shortest-path tree per this, at start
PREPARING = 'normal (preparing)'
PROVE_TILES = 64                  # then this many tiles of forbidden-space cells (8 ms)


class RequestError(ValueError):
    """A plan_path request that cannot be planned as asked."""


def yaw_from_quaternion(q) -> float:
    """The rotation about z of a quaternion that is one (x = y = 0 after normalising)."""
    values = [q.x, q.y, q.z, q.w]
    if not all(math.isfinite(v) for v in values):
        raise RequestError(f'start orientation {values} is not finite')
    norm = math.sqrt(sum(v * v for v in values))
    if norm < 1e-9:
        raise RequestError('start orientation is the zero quaternion: expected a rotation '
                           'about z carrying yaw = shoulder + elbow')
    x, y, z, w = (v / norm for v in values)
    if math.hypot(x, y) > 1e-3:
        raise RequestError(f'start orientation [{x:.3f}, {y:.3f}, {z:.3f}, {w:.3f}] is not a '
                           'rotation about z: the arm moves in the x-y plane')
    return 2.0 * math.atan2(z, w)


class PlannerNode(Node):

    def __init__(self):
        super().__init__('planner')
        params = declare_parameters(self, 'planner')
        self.arm = ArmConfig.from_parameters(params)
        self.config = PlannerConfig.from_parameters(params)
        self.started_s = time.monotonic()
        # The branch choice's timing kernels, before it serves: loaded for a first request
        # on a busy machine they could take longer than the controller's planner timeout.
        compile_kernels()
        began = time.monotonic()
        self.planner = Planner(self.arm, self.config)
        self.last_plan = None                # ((start, goal), plan): the last answer
        self.ranking = BranchRanking(self.arm)
        self.preset_answers = PresetAnswers(self.ranking, self.planner)
        self.build_s = time.monotonic() - began
        self.kinematics = self.planner.kinematics
        self.counts = {'plans': 0, 'no plan': 0, 'rejected requests': 0}
        self.last_message = 'no request yet'
        self.last_ok = True
        self.last_latency_s = math.nan
        self.scheduling = PREPARING          # or why real-time priority was refused

        self.path_pub = self.create_publisher(Path, 'planned_path', LATCHED)
        self.map_pub = self.create_publisher(OccupancyGrid, 'cspace_map', LATCHED)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_service(GetPlan, 'plan_path', self.on_plan_path)
        self.create_timer(1.0, self.publish_diagnostics)
        # While idle after start-up, one preset branch's tree per tick (Planner.prepare),
        # then one answer between presets (PresetAnswers), then PROVE_TILES of the cells the
        # checks look up (Planner.prove_cells, then the branch choice's: BranchRanking's).
        self.to_prepare = self.ranking.preset_configurations()
        self.cells_proved = False
        self.prepare_timer = self.create_timer(PREPARE_PERIOD_S, self.prepare_next)
        self.map_pub.publish(self.cspace_map())
        grid = self.planner.grid
        self.get_logger().info(
            f'configuration space: {grid.shoulder.count} x {grid.elbow.count} cells of '
            f'{math.degrees(grid.resolution_rad):.2f} deg, {100 * grid.free.mean():.0f}% free, '
            f'{len(self.arm.world.regions)} forbidden regions; built in {self.build_s:.2f} s')

    def prepare_next(self) -> None:
        """One tree, one answer or one slice of cells, then a pause of twice what it took: the
        executor takes a due timer before a waiting request, so work done back to back (a
        loaded machine, where one takes longer than the period) would keep plan_path waiting
        until the end."""
        self.destroy_timer(self.prepare_timer)
        prepared = not self.to_prepare and not self.preset_answers.pending
        if prepared and self.scheduling == PREPARING:
            self.answer_at_real_time()              # the cells are proved at that priority
        if prepared and self.cells_proved:
            self.get_logger().info(
                f'prepared {time.monotonic() - self.started_s:.1f} s after start: '
                f'{self.preset_answers.ready} answers between presets, every cell proved')
            return
        began = time.monotonic()
        try:
            if self.to_prepare:
                self.planner.prepare(self.to_prepare.pop(0))
            elif self.preset_answers.pending:
                self.preset_answers.prepare_next()
            else:
                self.cells_proved = (self.planner.prove_cells(PROVE_TILES)
                                     and self.ranking.prove_cells(PROVE_TILES))
        except Exception as error:                  # a failed table is no reason to stop
            self.get_logger().error(f'preparing the preset paths failed: {error!r}; '
                                    'answering without the rest of them')
            if self.scheduling == PREPARING:
                self.answer_at_real_time()
            return
        pause_s = max(PREPARE_PERIOD_S, 2.0 * (time.monotonic() - began))
        self.prepare_timer = self.create_timer(pause_s, self.prepare_next)

    def answer_at_real_time(self) -> None:
        """Prepared, the planner sleeps until a request: from now on every thread of it (the
        DDS threads that receive a request included) runs at ``realtime_priority``, so that
        a goal does not wait behind busy processes for its plan (at normal priority on a busy
        machine it would wait for a share of a core)."""
        problem = realtime.raise_process(self.config.realtime_priority)
        if problem:
            self.get_logger().warning(problem)
        self.scheduling = problem or (f'SCHED_FIFO {self.config.realtime_priority}'
                                      if self.config.realtime_priority else 'normal')

    # plan_path

    def on_plan_path(self, request, response):
        response.plan = Path()
        response.plan.header.frame_id = FRAME_ID
        response.plan.header.stamp = self.get_clock().now().to_msg()
        try:
            return self.answer(request, response)
        except Exception as error:                     # never let a request stop the node
            self.last_ok = False
            self.last_message = f'plan_path failed unexpectedly: {error!r}'
            self.get_logger().error(f'{self.last_message}; answering with an empty path')
            response.plan.poses = []
            return response

    def answer(self, request, response):
        began = time.monotonic()
        try:
            start_q = self.start_configuration(request.start)
            goal_xy = self.goal_point(request.goal)
        except RequestError as error:
            self.counts['rejected requests'] += 1
            self.last_ok = False
            self.last_message = f'rejected a plan_path request: {error}'
            self.get_logger().warning(f'{self.last_message}; answering with an empty path',
                                      throttle_duration_sec=1.0)
            return response
        plan = self.plan(start_q, goal_xy)
        self.last_latency_s = time.monotonic() - began
        goal_text = f'({goal_xy[0]:.3f}, {goal_xy[1]:.3f}) m'
        if not plan.ok:
            self.counts['no plan'] += 1
            self.last_ok = False
            self.last_message = (f'no plan: {plan.reason}' if goal_text in plan.reason
                                 else f'no plan to {goal_text}: {plan.reason}')
            self.get_logger().warning(self.last_message)
            return response
        self.counts['plans'] += 1
        self.last_ok = True
        response.plan.poses = [self.pose_stamped(pose, response.plan.header)
                               for pose in poses_from_waypoints(self.kinematics,
                                                                plan.waypoints_rad)]
        self.path_pub.publish(response.plan)
        self.last_message = (f'planned to {goal_text}: {len(plan.waypoints_rad)} waypoints, '
                             f'{math.degrees(plan.cost_rad):.1f} deg of joint travel')
        escape = self.planner.forbidden.why_forbidden(plan.waypoints_rad[0])
        if escape is not None:
            self.last_message += f'; the start is in forbidden space ({escape}), so the ' \
                'path first takes the shortest way out'
        # Each answer at debug (its last in /diagnostics): the controller asks for the paths
        # between presets at start, and the goals' own lines are the controller's.
        self.get_logger().debug(f'{self.last_message} ({1000 * self.last_latency_s:.1f} ms)')
        return response

    def plan(self, start_q, goal_xy):
        """The elbow branch that gets there soonest, as the controller would choose it
        (``BranchRanking.plan``); the planner's own choice for a goal without a clear branch.
        A request made again (a client whose answer may have been lost) gets the last answer
        at once, not a second search."""
        key = (tuple(np.asarray(start_q, float)), tuple(goal_xy))
        if self.last_plan is None or self.last_plan[0] != key:
            self.last_plan = (key, self.preset_answers.plan(start_q, goal_xy))
        return self.last_plan[1]

    def check_frame(self, header, what: str) -> None:
        if header.frame_id not in ('', FRAME_ID):
            raise RequestError(f'{what} is in frame {quote(header.frame_id)}, expected '
                               f"'{FRAME_ID}' (there is no TF here to transform it)")

    def start_configuration(self, start: PoseStamped) -> np.ndarray:
        """The joint configuration whose tool pose is ``start``, in the joints' travel."""
        self.check_frame(start.header, 'the start')
        position = start.pose.position
        x, y, z = position.x, position.y, position.z
        if not all(math.isfinite(v) for v in (x, y, z)):
            raise RequestError(f'start position ({x}, {y}, {z}) is not finite')
        yaw = yaw_from_quaternion(start.pose.orientation)
        q = self.kinematics.configuration_from_pose(x, y, yaw)
        x_check, y_check = self.kinematics.forward(q)
        if math.hypot(x_check - x, y_check - y) > POSE_TOLERANCE_M:
            x_elbow = x - self.kinematics.fore_m * math.cos(yaw)
            y_elbow = y - self.kinematics.fore_m * math.sin(yaw)
            raise RequestError(
                f'start pose (x {x:.3f} m, y {y:.3f} m, yaw {math.degrees(yaw):.1f} deg) is not '
                f'a pose of this arm: its elbow would be {math.hypot(x_elbow, y_elbow):.3f} m '
                f'from the shoulder, the upper arm is {self.kinematics.upper_m:.3f} m long')
        return np.array(q)

    def goal_point(self, goal: PoseStamped) -> tuple[float, float]:
        self.check_frame(goal.header, 'the goal')
        position = goal.pose.position
        x, y, z = position.x, position.y, position.z
        if not all(math.isfinite(v) for v in (x, y, z)):
            raise RequestError(f'goal position ({x}, {y}, {z}) is not finite')
        if abs(z) > PLANE_TOLERANCE_M:
            raise RequestError(f'goal z = {z:.4f} m: the arm moves in the plane z = 0')
        return x, y

    def pose_stamped(self, pose, header) -> PoseStamped:
        x, y, yaw = pose
        msg = PoseStamped(header=header)
        msg.pose.position.x, msg.pose.position.y = x, y
        msg.pose.orientation = messages.quaternion_from_yaw(yaw)
        return msg

    # cspace_map and diagnostics

    def cspace_map(self) -> OccupancyGrid:
        grid = self.planner.grid
        msg = OccupancyGrid()
        msg.header.frame_id = CSPACE_FRAME
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.info.map_load_time = msg.header.stamp
        msg.info.resolution = float(grid.resolution_rad)
        msg.info.width = grid.shoulder.count
        msg.info.height = grid.elbow.count
        msg.info.origin.position.x = grid.shoulder.first_rad - 0.5 * grid.resolution_rad
        msg.info.origin.position.y = grid.elbow.first_rad - 0.5 * grid.resolution_rad
        msg.info.origin.orientation.w = 1.0
        # Row j (elbow) holds the shoulder cells i: data[j * width + i].
        msg.data = np.where(grid.free.T, 0, 100).astype(np.int8).ravel().tolist()
        return msg

    def publish_diagnostics(self) -> None:
        grid, answers = self.planner.grid, self.preset_answers
        level = DiagnosticStatus.OK if self.last_ok else DiagnosticStatus.WARN
        diagnostic = DiagnosticArray()
        diagnostic.header.stamp = self.get_clock().now().to_msg()
        diagnostic.status = [status(self, level, self.last_message, {
            **self.counts,
            'last query (ms)': f'{1000 * self.last_latency_s:.1f}',
            'grid cells (shoulder x elbow)': f'{grid.shoulder.count} x {grid.elbow.count}',
            'grid resolution (deg)': f'{math.degrees(grid.resolution_rad):.3f}',
            'free fraction': f'{grid.free.mean():.3f}',
            'blocked grid edges found': grid.blocked_edges,
            'build time (s)': f'{self.build_s:.3f}',
            'scheduling': self.scheduling,
            'answers between presets ready': f'{answers.ready} of '
                                             f'{answers.ready + len(answers.pending)}',
            'every cell proved': 'yes' if self.cells_proved else 'no',
        })]
        self.diagnostics_pub.publish(diagnostic)


def main(args=None):
    sys.exit(run(PlannerNode, args))


if __name__ == '__main__':
    main()
