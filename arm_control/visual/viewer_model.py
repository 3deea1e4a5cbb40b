"""What the viewer knows, kept from messages as plain data: no ROS here.

The viewer shows the goals it has heard on ``goal_point`` as the controller's queue: a goal
leaves the queue when the tool comes within ``goal_reached_m`` of it (the first goal only:
goals are visited in order), and the queue empties when the controller goes back to
waiting with nothing to do. Goals no allowed configuration reaches are not queued (the
controller rejects them too).
"""

from dataclasses import dataclass
import math
import re
from typing import Any, Mapping

from arm_control.config import ArmConfig, FRAME_ID
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.world import ForbiddenSpace
from arm_control.parameters import ParameterError
from arm_control.text import quote
from arm_control.visual.scene import path_configurations, reachable_free, Scene

MAX_GOALS = 256                 # goals shown at most; a flood beyond this is not drawn
STALE_AFTER_S = 0.5             # joint states older than this are called out on the picture
GOAL_FRAMES = ('', FRAME_ID)
GOAL_Z_TOLERANCE_M = 1e-3
PATH_START_RAD = 0.05           # a path begins at the arm when within this on both joints


@dataclass(frozen=True)
class ViewerConfig:
    """The viewer's own parameters (section ``/viewer`` of config/arm.yaml)."""

    rate_hz: float
    png_rate_hz: float
    png_path: str
    headless: bool
    goal_reached_m: float

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> 'ViewerConfig':
        def number(name):
            value = params.get(name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or value <= 0.0:
                raise ParameterError(f"parameter '{name}' = {value!r}: must be a number > 0")
            return float(value)

        png_path, headless = params.get('png_path'), params.get('headless')
        if not isinstance(png_path, str) or not png_path:
            raise ParameterError(f"parameter 'png_path' = {png_path!r}: expected a file name")
        if not isinstance(headless, bool):
            raise ParameterError(f"parameter 'headless' = {headless!r}: expected true or false")
        return cls(rate_hz=number('rate_hz'), png_rate_hz=number('png_rate_hz'),
                   png_path=png_path, headless=headless,
                   goal_reached_m=number('goal_reached_m'))


def is_idle_state(state: str) -> bool:
    """States in which the controller has no goal left: waiting (or idle)."""
    letters = re.sub(r'[^a-z]', '', state.lower())
    return 'wait' in letters or 'idle' in letters


def has_no_goal(state: str) -> bool:
    """States in which a planned path is not the arm's: the controller, holding or waiting,
    asks for the paths between presets ahead of time, and the planner publishes those too."""
    return state in ('holding', 'waiting')


class ViewerModel:
    """The latest of everything the viewer draws, updated by message contents."""

    def __init__(self, arm: ArmConfig, goal_reached_m: float = 0.03):
        self.arm = arm
        self.space = ForbiddenSpace(arm)
        self.kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
        self.goal_reached_m = goal_reached_m
        self.joint_rad: tuple[float, float] | None = None
        self.joint_time_s = -math.inf
        self.setpoint_rad: tuple[float, float] | None = None
        self.state = ''
        self.path_rad: tuple[tuple[float, float], ...] = ()     # of the arm's last move
        self.idle_path_rad: tuple[tuple[float, float], ...] = ()
        self.goals: list[tuple[float, float]] = []
        self.ghost_xy: tuple[float, float] | None = None

    def on_joint_state(self, position, now_s: float) -> str | None:
        """A measured (shoulder, elbow); returns why it was refused, or None."""
        position = list(position)
        if len(position) < 2 or not all(_finite(p) for p in position[:2]):
            return f'joint state position {position}: expected 2 finite angles (rad)'
        self.joint_rad = (float(position[0]), float(position[1]))
        self.joint_time_s = now_s
        tool = self.kinematics.forward(self.joint_rad)
        while self.goals and math.dist(tool, self.goals[0]) <= self.goal_reached_m:
            self.goals.pop(0)
        return None

    def on_setpoint(self, position) -> str | None:
        position = list(position)
        if len(position) < 2 or not all(_finite(p) for p in position[:2]):
            return f'setpoint position {position}: expected 2 finite angles (rad)'
        self.setpoint_rad = (float(position[0]), float(position[1]))
        return None

    def on_goal(self, x: float, y: float, z: float = 0.0, frame_id: str = '') -> str | None:
        """Queue a goal as the controller would; returns why it is not queued, or None."""
        if not all(_finite(v) for v in (x, y, z)):
            return f'goal ({x}, {y}, {z}) is not finite'
        if frame_id not in GOAL_FRAMES:
            return f'goal in frame {quote(frame_id)}: only arm_base is understood'
        if abs(z) > GOAL_Z_TOLERANCE_M:
            return f'goal z = {z:.3f} m: the arm moves in the plane z = 0'
        if not reachable_free(self.space, x, y):
            return f'goal ({x:.2f}, {y:.2f}) m: no allowed configuration reaches it'
        if len(self.goals) >= MAX_GOALS:
            return f'{MAX_GOALS} goals shown already: goal ({x:.2f}, {y:.2f}) not drawn'
        self.goals.append((float(x), float(y)))
        return None

    def on_state(self, state: str) -> None:
        if is_idle_state(state) and not is_idle_state(self.state):
            self.goals.clear()
        if not has_no_goal(state) and has_no_goal(self.state) and self.idle_path_rad \
                and self._starts_at_the_arm(self.idle_path_rad):
            self.path_rad = self.idle_path_rad      # the goal's path came before its state
        self.state = state

    def on_path(self, poses) -> str | None:
        """The planned path as tool poses (x, y, yaw); an empty one clears it."""
        poses = [tuple(p) for p in poses]
        if not all(len(p) == 3 and all(_finite(v) for v in p) for p in poses):
            return 'planned path with non-finite poses: ignored'
        path_rad = path_configurations(self.space, poses)
        if has_no_goal(self.state):
            self.idle_path_rad = path_rad           # not a move: the controller planning ahead
        else:
            self.path_rad = path_rad
        return None

    def _starts_at_the_arm(self, path_rad) -> bool:
        return self.joint_rad is not None and max(
            abs(a - b) for a, b in zip(path_rad[0], self.joint_rad)) <= PATH_START_RAD

    def scene(self, now_s: float) -> Scene:
        note = ''
        if self.joint_rad is not None and now_s - self.joint_time_s > STALE_AFTER_S:
            note = f'no joint_states for {now_s - self.joint_time_s:.1f} s'
        return Scene(joint_rad=self.joint_rad, state=self.state, path_rad=self.path_rad,
                     goals_xy=tuple(self.goals), ghost_xy=self.ghost_xy,
                     setpoint_rad=self.setpoint_rad, note=note)


def _finite(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)
