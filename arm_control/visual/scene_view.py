"""The viewer's picture drawn with matplotlib: ``SceneView(arm)``, no ROS.

It draws what does not move once -- the reachable annulus, shaded where some allowed
configuration really puts the tool; the forbidden regions grown by their clearance; the
configuration space beside it -- and ``update(Scene(...))`` moves the rest: the arm in its
state's colour (as in the seed program), the state as coloured text, the planned path as the
tool's trace, the queued goals, the trajectory setpoint and the ghost of the point under the
mouse. Headless it renders to PNG (``render_png``) or to pixels (``render_rgb``); in a window
the viewer node hands it a pyplot figure.
"""

import math

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
import numpy as np

from arm_control.config import ArmConfig
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.world import ForbiddenSpace
from arm_control.visual.scene import (ARM_WIDTH_PX, BLOCKED_COLOUR, cspace_image,
                                      CSpaceImage, densify, draw_world, FORBIDDEN_COLOUR,
                                      GOAL_COLOUR, MAX_GOAL_LABELS, PATH_COLOUR, REACH_COLOUR,
                                      reachable_free, rgb, Scene, SETPOINT_COLOUR,
                                      state_colour, SWEEP_POSES, workspace_extent)


class SceneView:
    """A figure with the workspace (left) and the configuration space (right).

    ``figure``: a pyplot figure for a window; by default a headless Agg figure of
    ``size_px`` pixels. ``cspace``: the planner's map, else computed here at 2°.
    """

    def __init__(self, arm: ArmConfig, *, size_px=None, dpi: float = 100.0, figure=None,
                 workspace_step_m: float = 0.01):
        self.arm = arm
        self.kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
        self.space = ForbiddenSpace(arm)
        self.extent = workspace_extent(arm)
        if figure is None:
            width_px, height_px = size_px or self.natural_size_px(self.extent)
            figure = Figure(figsize=(width_px / dpi, height_px / dpi), dpi=dpi)
            FigureCanvasAgg(figure)
        self.figure = figure
        self.points_per_px = 72.0 / figure.dpi
        figure.set_facecolor('#f1f3f5')
        width_px, height_px = figure.get_size_inches() * figure.dpi
        # 55 px left, the workspace 62 % of the width, the configuration space 23 %.
        self.workspace = figure.add_axes(
            (55 / width_px, 50 / height_px, 0.62, 1.0 - 80 / height_px))
        self.cspace_axes = figure.add_axes(
            (1.0 - 20 / width_px - 0.23, 80 / height_px, 0.23, 1.0 - 140 / height_px))
        draw_world(self.workspace, arm, self.space, self.extent, workspace_step_m)
        self._cspace_artist = None
        self.set_cspace(cspace_image(self.space))
        self._make_moving_artists()

    @staticmethod
    def natural_size_px(extent, width_px: int = 1000) -> tuple[int, int]:
        """A figure size that the workspace, drawn to scale, fills without margins."""
        x_min, x_max, y_min, y_max = extent
        workspace_height_px = 0.62 * width_px * (y_max - y_min) / (x_max - x_min)
        return width_px, int(round(max(workspace_height_px, 300) + 80))

    # -- what does not move ------------------------------------------------------------

    def set_cspace(self, image: CSpaceImage) -> None:
        """Show this configuration space (e.g. the planner's ``cspace_map``)."""
        ax = self.cspace_axes
        if self._cspace_artist is not None:
            self._cspace_artist.remove()
        shade = np.where(image.occupied[..., None], rgb(FORBIDDEN_COLOUR), 1.0)
        self._cspace_artist = ax.imshow(shade, origin='lower', extent=image.extent_deg,
                                        interpolation='nearest', aspect='auto', zorder=0)
        ax.set_xlim(image.extent_deg[0], image.extent_deg[1])
        ax.set_ylim(image.extent_deg[2], image.extent_deg[3])
        ax.set_title('configuration space', fontsize=9)
        ax.set_xlabel('shoulder (deg)', fontsize=8)
        ax.set_ylabel('elbow (deg)', fontsize=8)
        ax.tick_params(labelsize=7)
        self._background = None                 # a live window redraws it in full

    # -- what moves --------------------------------------------------------------------

    def _make_moving_artists(self) -> None:
        ax, cs = self.workspace, self.cspace_axes
        px = self.points_per_px
        self._sweep = LineCollection([], linewidths=ARM_WIDTH_PX * px * 0.7, alpha=0.10,
                                     capstyle='round', zorder=5)
        ax.add_collection(self._sweep)
        (self._path_line,) = ax.plot([], [], color=PATH_COLOUR, linewidth=2.0, zorder=6)
        (self._path_points,) = ax.plot([], [], 'o', color=PATH_COLOUR, markersize=4, zorder=6)
        (self._setpoint_arm,) = ax.plot([], [], color=SETPOINT_COLOUR, linewidth=1.5,
                                        linestyle=(0, (4, 3)), zorder=7)
        (self._arm,) = ax.plot([], [], linewidth=ARM_WIDTH_PX * px, solid_capstyle='round',
                               zorder=10)
        (self._joints,) = ax.plot([], [], 'o', markersize=11 * px, markerfacecolor='white',
                                  markeredgecolor='#212529', markeredgewidth=1.5, zorder=11)
        (self._goals,) = ax.plot([], [], 'o', color=GOAL_COLOUR, markersize=15 * px,
                                 markeredgecolor='white', markeredgewidth=1.0, zorder=12)
        self._goal_labels = [
            ax.text(0, 0, str(i + 1), ha='center', va='center', fontsize=7, color='white',
                    fontweight='bold', zorder=13, visible=False)
            for i in range(MAX_GOAL_LABELS)]
        (self._ghost,) = ax.plot([], [], linestyle='none', markersize=14 * px, alpha=0.7,
                                 zorder=14)
        self._ghost_text = ax.text(0, 0, '', fontsize=8, va='center', zorder=14, visible=False,
                                   clip_on=True)
        self._state_text = ax.text(0.985, 0.975, '', transform=ax.transAxes, ha='right',
                                   va='top', fontsize=17, fontweight='bold', zorder=15)
        self._note_text = ax.text(0.985, 0.90, '', transform=ax.transAxes, ha='right',
                                  va='top', fontsize=9, color='#343a40', zorder=15)
        self._info_text = ax.text(0.015, 0.975, '', transform=ax.transAxes, ha='left',
                                  va='top', fontsize=8.5, family='monospace', color='#343a40',
                                  zorder=15, bbox=dict(facecolor='white', alpha=0.75,
                                                       edgecolor='none', pad=2.0))
        (self._cs_path,) = cs.plot([], [], color=PATH_COLOUR, linewidth=1.5, zorder=2)
        (self._cs_goals,) = cs.plot([], [], 'o', markerfacecolor='none', markersize=6,
                                    markeredgecolor=GOAL_COLOUR, markeredgewidth=1.5, zorder=3)
        (self._cs_setpoint,) = cs.plot([], [], '+', color=SETPOINT_COLOUR, markersize=9,
                                       zorder=4)
        (self._cs_arm,) = cs.plot([], [], 'o', markersize=7, markeredgecolor='white', zorder=5)

    def _arm_points(self, q) -> np.ndarray:
        return np.array([(0.0, 0.0), self.kinematics.elbow_point(q), self.kinematics.forward(q)])

    def update(self, scene: Scene) -> None:
        """Move every moving artist to ``scene``; drawing is left to the caller's canvas."""
        colour = state_colour(scene.state)
        self._state_text.set_text(scene.state.upper() or 'NO STATE')
        self._state_text.set_color(colour)
        self._note_text.set_text(scene.note)

        if scene.joint_rad is not None and all(map(math.isfinite, scene.joint_rad)):
            points = self._arm_points(scene.joint_rad)
            self._arm.set_data(points[:, 0], points[:, 1])
            self._arm.set_color(colour)
            self._joints.set_data(points[:2, 0], points[:2, 1])
            self._cs_arm.set_data([math.degrees(scene.joint_rad[0])],
                                  [math.degrees(scene.joint_rad[1])])
            self._cs_arm.set_color(colour)
            shoulder, elbow = scene.joint_rad
            x, y = points[2]
            self._info_text.set_text(
                f'shoulder {math.degrees(shoulder):7.1f}°   elbow {math.degrees(elbow):7.1f}°\n'
                f'tool     ({x:5.2f}, {y:5.2f}) m\n'
                f'goals    {len(scene.goals_xy)} queued')
        else:
            for artist in (self._arm, self._joints, self._cs_arm):
                artist.set_data([], [])
            self._info_text.set_text(f'no joint_states yet\ngoals    {len(scene.goals_xy)} '
                                     'queued')

        self._update_path(scene.path_rad, colour)
        self._update_setpoint(scene.setpoint_rad)
        self._update_goals(scene.goals_xy)
        self._update_ghost(scene.ghost_xy)

    def _update_path(self, path_rad, colour) -> None:
        if len(path_rad) == 0:
            for artist in (self._path_line, self._path_points, self._cs_path):
                artist.set_data([], [])
            self._sweep.set_segments([])
            return
        dense = densify(path_rad)
        tool = np.array([self.kinematics.forward(q) for q in dense])
        waypoints = np.array([self.kinematics.forward(q) for q in path_rad])
        self._path_line.set_data(tool[:, 0], tool[:, 1])
        self._path_points.set_data(waypoints[:, 0], waypoints[:, 1])
        self._cs_path.set_data(np.degrees(dense[:, 0]), np.degrees(dense[:, 1]))
        picks = dense[np.linspace(0, len(dense) - 1, SWEEP_POSES).round().astype(int)]
        self._sweep.set_segments([self._arm_points(q) for q in picks])
        self._sweep.set_color(colour)

    def _update_setpoint(self, setpoint_rad) -> None:
        if setpoint_rad is None or not all(map(math.isfinite, setpoint_rad)):
            self._setpoint_arm.set_data([], [])
            self._cs_setpoint.set_data([], [])
            return
        points = self._arm_points(setpoint_rad)
        self._setpoint_arm.set_data(points[:, 0], points[:, 1])
        self._cs_setpoint.set_data([math.degrees(setpoint_rad[0])],
                                   [math.degrees(setpoint_rad[1])])

    def _update_goals(self, goals_xy) -> None:
        goals = np.asarray(goals_xy, float).reshape(-1, 2)
        self._goals.set_data(goals[:, 0], goals[:, 1])
        for i, label in enumerate(self._goal_labels):
            label.set_visible(i < len(goals))
            if i < len(goals):
                label.set_position(goals[i])
        branches = []
        for x, y in goals:
            if self.kinematics.is_reachable(x, y):
                for q in self.kinematics.inverse(x, y):
                    shoulder = self.space.to_joint_range(q[0], 0)
                    if shoulder is not None and self.space.is_free((shoulder, q[1])):
                        branches.append((math.degrees(shoulder), math.degrees(q[1])))
        branches = np.array(branches).reshape(-1, 2)
        self._cs_goals.set_data(branches[:, 0], branches[:, 1])

    def _update_ghost(self, ghost_xy) -> None:
        if ghost_xy is None or not all(map(math.isfinite, ghost_xy)):
            self._ghost.set_data([], [])
            self._ghost_text.set_visible(False)
            return
        x, y = ghost_xy
        free = bool(reachable_free(self.space, x, y))
        self._ghost.set_data([x], [y])
        self._ghost.set_marker('o' if free else 'X')
        self._ghost.set_color(REACH_COLOUR if free else BLOCKED_COLOUR)
        label = f'({x:.2f}, {y:.2f})' + ('' if free else ' not reachable')
        on_the_left = x > 0.5 * (self.extent[0] + self.extent[1])
        self._ghost_text.set_text(f'{label}   ' if on_the_left else f'   {label}')
        self._ghost_text.set_horizontalalignment('right' if on_the_left else 'left')
        self._ghost_text.set_position((x, y))
        self._ghost_text.set_color(REACH_COLOUR if free else BLOCKED_COLOUR)
        self._ghost_text.set_visible(True)

    # -- output ------------------------------------------------------------------------

    def moving_artists(self) -> list:
        return [self._sweep, self._path_line, self._path_points, self._setpoint_arm, self._arm,
                self._joints, self._goals, *self._goal_labels, self._ghost, self._ghost_text,
                self._state_text, self._note_text, self._info_text, self._cs_path,
                self._cs_goals, self._cs_setpoint, self._cs_arm]

    def start_live(self) -> None:
        """Draw frames by blitting from now on (``draw_live``): the world, axes and ticks are
        drawn once and kept as a background; each frame draws only what moves.
        Only for a window: frames then never reach ``render_png``."""
        self._background = None
        for artist in self.moving_artists():
            artist.set_animated(True)
        self.figure.canvas.mpl_connect('draw_event', self._on_full_draw)

    def _on_full_draw(self, event) -> None:
        canvas = self.figure.canvas
        self._background = canvas.copy_from_bbox(self.figure.bbox)
        self._draw_moving()

    def _draw_moving(self) -> None:
        for artist in self.moving_artists():
            self.figure.draw_artist(artist)

    def draw_live(self, scene: Scene) -> None:
        """Show ``scene`` in the window (after ``start_live``)."""
        self.update(scene)
        canvas = self.figure.canvas
        if self._background is None:
            canvas.draw()                       # the full draw stores the background
        else:
            canvas.restore_region(self._background)
            self._draw_moving()
        canvas.blit(self.figure.bbox)

    def render_rgb(self, scene: Scene) -> np.ndarray:
        """The frame as an (height, width, 3) uint8 array, row 0 at the top."""
        self.update(scene)
        self.figure.canvas.draw()
        return np.asarray(self.figure.canvas.buffer_rgba())[..., :3].copy()

    def render_png(self, scene: Scene, path) -> None:
        self.update(scene)
        self.figure.savefig(path, format='png', dpi=self.figure.dpi,
                            facecolor=self.figure.get_facecolor())

    def pixel_of(self, x_m: float, y_m: float) -> tuple[int, int]:
        """(column, row) in the rendered picture of the point (x, y) of arm_base."""
        self.workspace.apply_aspect()       # where drawing puts the axes box
        column, height_up = self.workspace.transData.transform((x_m, y_m))
        height = self.figure.canvas.get_width_height()[1]
        return int(round(column)), int(round(height - height_up))

    def workspace_point(self, event) -> tuple[float, float] | None:
        """The arm_base point under a matplotlib mouse event, if it is over the workspace."""
        if event.inaxes is not self.workspace or event.xdata is None:
            return None
        return float(event.xdata), float(event.ydata)
