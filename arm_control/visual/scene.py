"""What the viewer shows, as plain data, and the world it is drawn on: no ROS here.

A ``Scene`` is one instant -- the arm, its state, the planned path, the goals, the setpoint,
the ghost under the mouse; ``draw_world`` draws what never moves; ``scene_view.SceneView``
puts both on a figure.
"""

from dataclasses import dataclass
import math
import re

from matplotlib import patches
import numpy as np

from arm_control.config import ArmConfig
from arm_control.model.kinematics import TwoLinkKinematics, wrap_angle
from arm_control.model.world import ForbiddenSpace

# The arm takes its state's colour: (word in the state's name, colour), first match wins.
STATE_COLOURS = (
    ('estop', '#e03131'), ('emergency', '#e03131'),     # red: stopped hard, needs a reset
    ('error', '#f08c00'), ('fault', '#f08c00'), ('reject', '#f08c00'),
    ('disabl', '#adb5bd'),
    ('sensor', '#868e96'),                              # no sensors: nothing to close a loop on
    ('driver', '#9c36b5'), ('velocity', '#9c36b5'), ('manual', '#9c36b5'),
    ('track', '#1971c2'), ('mov', '#1971c2'), ('plan', '#1971c2'),
    ('hold', '#2f9e44'), ('finish', '#2f9e44'), ('done', '#2f9e44'), ('reach', '#2f9e44'),
    ('wait', '#495057'), ('idle', '#495057'),
)
UNKNOWN_STATE_COLOUR = '#212529'
PATH_COLOUR = '#0c8599'
GOAL_COLOUR = '#d6336c'
FORBIDDEN_COLOUR = '#868e96'
REACH_COLOUR = '#2f9e44'
BLOCKED_COLOUR = '#e03131'
SETPOINT_COLOUR = '#495057'
BACKGROUND_COLOUR = '#ffffff'

ARM_WIDTH_PX = 9.0
SWEEP_POSES = 7                     # faint arm poses drawn along the planned path
MAX_GOAL_LABELS = 30


def state_colour(state: str) -> str:
    """The colour of a state machine state, by the words in its name ('E-STOPPED' → red)."""
    letters = re.sub(r'[^a-z]', '', (state or '').lower())
    return next((colour for word, colour in STATE_COLOURS if word in letters),
                UNKNOWN_STATE_COLOUR)


@dataclass(frozen=True)
class Scene:
    """One frame: where the arm is and what it is doing. Angles in rad, points in arm_base m."""

    joint_rad: tuple[float, float] | None = None       # measured (shoulder, elbow)
    state: str = ''
    path_rad: tuple[tuple[float, float], ...] = ()     # the planned path, as configurations
    goals_xy: tuple[tuple[float, float], ...] = ()     # queued goals, first to be visited first
    ghost_xy: tuple[float, float] | None = None        # the point under the mouse
    setpoint_rad: tuple[float, float] | None = None    # the trajectory's position setpoint
    note: str = ''                                      # a line of status under the state


@dataclass(frozen=True)
class CSpaceImage:
    """Forbidden cells of the (shoulder, elbow) grid: ``occupied[elbow row, shoulder col]``,
    cell (0, 0) centred at (shoulder_min_rad, elbow_min_rad) + resolution/2."""

    occupied: np.ndarray
    shoulder_min_rad: float
    elbow_min_rad: float
    resolution_rad: float

    @property
    def extent_deg(self) -> tuple[float, float, float, float]:
        rows, cols = self.occupied.shape
        return (math.degrees(self.shoulder_min_rad),
                math.degrees(self.shoulder_min_rad + cols * self.resolution_rad),
                math.degrees(self.elbow_min_rad),
                math.degrees(self.elbow_min_rad + rows * self.resolution_rad))


def cspace_from_occupancy(width: int, height: int, resolution_rad: float, origin_x: float,
                          origin_y: float, data) -> CSpaceImage:
    """The planner's ``cspace_map`` (OccupancyGrid, map x = shoulder, map y = elbow, row-major
    with y rows): cells at 50 or more (and unknown, -1) count as forbidden."""
    cells = np.asarray(data, dtype=np.int16).reshape(height, width)
    return CSpaceImage((cells >= 50) | (cells < 0), origin_x, origin_y, resolution_rad)


def cspace_image(space: ForbiddenSpace, resolution_rad: float = math.radians(2.0)) -> CSpaceImage:
    """The configuration space over the joint limits, each cell judged at its centre."""
    (s_min, s_max), (e_min, e_max) = space.limits
    shoulder = np.arange(s_min, s_max, resolution_rad) + resolution_rad / 2
    elbow = np.arange(e_min, e_max, resolution_rad) + resolution_rad / 2
    grid = np.stack(np.meshgrid(shoulder, elbow), axis=-1)     # [elbow row, shoulder col, 2]
    return CSpaceImage(~np.asarray(space.is_free(grid)), s_min, e_min, resolution_rad)


def reachable_free(space: ForbiddenSpace, x, y) -> np.ndarray:
    """Whether some allowed configuration puts the tool at (x, y): either IK branch, the
    shoulder taken in whichever turn fits its limits. Vectorised over arrays of points."""
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    la, lb = space.upper_m, space.fore_m
    cos_elbow = (x * x + y * y - la * la - lb * lb) / (2.0 * la * lb)
    within_reach = np.abs(cos_elbow) <= 1.0 + 1e-12
    elbow = np.arccos(np.clip(cos_elbow, -1.0, 1.0))
    free = np.zeros(x.shape, dtype=bool)
    for branch in (elbow, -elbow):
        # θa = atan2(y, x) − atan2(Lb sin θb, La + Lb cos θb)
        shoulder = np.arctan2(y, x) - np.arctan2(lb * np.sin(branch), la + lb * np.cos(branch))
        for turn in (-2.0 * math.pi, 0.0, 2.0 * math.pi):
            free |= np.asarray(space.is_free(np.stack([shoulder + turn, branch], axis=-1)))
    return free & within_reach


def path_configurations(space: ForbiddenSpace, poses) -> tuple[tuple[float, float], ...]:
    """Tool poses (x, y, yaw) -> configurations inside the joint limits, each turn chosen
    nearest the previous one so that a path over the top stays continuous."""
    kinematics = TwoLinkKinematics(space.upper_m, space.fore_m)
    out = []
    for x, y, yaw in poses:
        shoulder, elbow = kinematics.configuration_from_pose(x, y, yaw)
        turns = [shoulder + 2.0 * math.pi * k for k in (-1, 0, 1)]
        inside = [s for s in turns if space.limits[0][0] <= s <= space.limits[0][1]] or turns
        reference = out[-1][0] if out else shoulder
        shoulder = min(inside, key=lambda s: abs(s - reference))
        out.append((shoulder, wrap_angle(elbow)))
    return tuple(out)


def densify(path_rad, step_rad: float = math.radians(2.0)) -> np.ndarray:
    """The straight joint-space segments between waypoints, sampled every ``step_rad``."""
    path = np.asarray(path_rad, float).reshape(-1, 2)
    if len(path) < 2:
        return path
    pieces = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        count = max(1, int(math.ceil(np.max(np.abs(b - a)) / step_rad)))
        pieces.append(a + np.linspace(0.0, 1.0, count + 1)[1:, None] * (b - a))
    return np.concatenate(pieces)


def workspace_extent(arm: ArmConfig, margin_m: float = 0.2) -> tuple[float, float, float, float]:
    """(x_min, x_max, y_min, y_max) to show: the reach disc, cut a little below any region
    (such as the floor) that fills the whole width beneath the arm."""
    reach = arm.reach_m[1] + margin_m
    bottom = -reach
    grow = arm.world.clearance_m
    for region in arm.world.regions:
        spans_width = region.x_min - grow <= -reach and region.x_max + grow >= reach
        if spans_width and region.y_min - grow <= -reach:
            bottom = max(bottom, region.y_max + grow - margin_m)
    return -reach, reach, min(bottom, -margin_m), reach


def draw_world(ax, arm: ArmConfig, space: ForbiddenSpace, extent, step_m: float = 0.01) -> None:
    """What does not move: the reachable annulus, shaded where an allowed configuration
    really puts the tool, and the forbidden regions grown by their clearance."""
    x_min, x_max, y_min, y_max = extent
    ax.set_xlim(x_min, x_max)
    ax.set_ylim(y_min, y_max)
    ax.set_aspect('equal', adjustable='box')
    ax.set_facecolor(BACKGROUND_COLOUR)
    ax.set_xlabel('x (m), arm_base', fontsize=9)
    ax.set_ylabel('y (m)', fontsize=9)
    ax.tick_params(labelsize=8)
    ax.grid(True, color='#e9ecef', linewidth=0.8, zorder=0)

    # Where the tool can be: reachable, by a configuration that is allowed.
    xs = np.arange(x_min, x_max, step_m) + step_m / 2
    ys = np.arange(y_min, y_max, step_m) + step_m / 2
    grid_x, grid_y = np.meshgrid(xs, ys)
    free = reachable_free(space, grid_x, grid_y)
    rgba = np.zeros(free.shape + (4,))
    rgba[..., :3] = rgb(REACH_COLOUR)
    rgba[..., 3] = np.where(free, 0.16, 0.0)
    ax.imshow(rgba, origin='lower', extent=(x_min, x_max, y_min, y_max),
              interpolation='nearest', zorder=1)
    inner, outer = arm.reach_m
    for radius in (inner, outer):
        if radius > 0.0:
            ax.add_patch(patches.Circle((0.0, 0.0), radius, fill=False, linestyle='--',
                                        linewidth=1.0, edgecolor=REACH_COLOUR, zorder=2))

    grow = arm.world.clearance_m
    for region in arm.world.regions:
        ax.add_patch(patches.Rectangle(
            (region.x_min - grow, region.y_min - grow),
            region.x_max - region.x_min + 2 * grow, region.y_max - region.y_min + 2 * grow,
            facecolor=FORBIDDEN_COLOUR, alpha=0.45, hatch='///', edgecolor='#495057',
            linewidth=1.0, zorder=3))
        if grow > 0.0:
            ax.add_patch(patches.Rectangle(
                (region.x_min, region.y_min), region.x_max - region.x_min,
                region.y_max - region.y_min, fill=False, edgecolor='#343a40',
                linewidth=1.2, zorder=3))
        label_x = (max(region.x_min, x_min) + min(region.x_max, x_max)) / 2
        label_y = (max(region.y_min, y_min) + min(region.y_max, y_max)) / 2
        visible_width = min(region.x_max, x_max) - max(region.x_min, x_min)
        visible_height = min(region.y_max, y_max) - max(region.y_min, y_min)
        if x_min < label_x < x_max and y_min < label_y < y_max:
            ax.text(label_x, label_y, region.name, ha='center', va='center', fontsize=8,
                    style='italic', color='#343a40', zorder=4, clip_on=True,
                    rotation=90 if visible_height > 2 * visible_width else 0)


def rgb(colour: str) -> np.ndarray:
    return np.array([int(colour[i:i + 2], 16) / 255.0 for i in (1, 3, 5)])
