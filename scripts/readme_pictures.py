"""A real closed-loop run without ROS, recorded, plotted and drawn: the README's pictures.

The controller core, the planner and the simulated arm run in one process, in simulated
time, at the controller's loop rate (``control.closed_loop.ClosedLoop``). Every period is
kept as a ``Sample`` (for ``plots.plot_run``) and as a ``Scene`` (for the viewer's picture).

    python scripts/readme_pictures.py docs/                          # the default arm
    python scripts/readme_pictures.py docs/ --params config/frc_robot.yaml --name frc_robot

writes ``<name>_viewer.png`` (the viewer mid-way through the longest move, path and goals
shown) and ``<name>_run.png`` (angles and setpoints, tracking error, voltage, states), and
prints the goals.
"""

import argparse
from dataclasses import dataclass, field
import math
from pathlib import Path
import sys

import numpy as np

from arm_control import config
from arm_control.control.closed_loop import ClosedLoop
from arm_control.logs.recording import Recording, Sample
from arm_control.planning.planner import Planner
from arm_control.visual.plots import plot_run
from arm_control.visual.scene import Scene
from arm_control.visual.scene_view import SceneView


class PlannerTap:
    """The planner, passed through, keeping the last path it returned (for the picture)."""

    def __init__(self, planner):
        self.planner = planner
        self.last_path_rad: tuple = ()

    def plan(self, start_q, goal_xy):
        return self._keep(self.planner.plan(start_q, goal_xy))

    def plan_to_configuration(self, start_q, goal_q):
        return self._keep(self.planner.plan_to_configuration(start_q, goal_q))

    def _keep(self, plan):
        if plan.ok:
            self.last_path_rad = tuple(map(tuple, np.asarray(plan.waypoints_rad)))
        return plan


@dataclass
class Run:
    samples: list = field(default_factory=list)         # Sample per control period
    scenes: list = field(default_factory=list)          # Scene per control period
    goals: list = field(default_factory=list)           # (label, x, y, reached at s or nan)
    events: list = field(default_factory=list)          # the controller's Event list


def closed_loop_run(params_files=(), goal_names=None, duration_s: float = 30.0,
                    seed: int = 0) -> Run:
    """Send the presets ``goal_names`` (default: every preset) at t = 0, queued, and run
    until all are reached and 1 s more, or ``duration_s``."""
    arm, sim_config = config.load('sim', *params_files)
    controller_config = config.load('controller', *params_files)[1]
    planner = PlannerTap(Planner(arm, config.load('planner', *params_files)[1]))
    loop = ClosedLoop(arm, controller_config, planner, sim_config.initial_position, seed,
                      sim_config.physics_step_s)
    presets = {name: (x, y) for name, x, y in arm.presets}
    names = list(goal_names or presets)
    run = Run()
    for name in names:
        ok, message = loop.core.submit_preset(0.0, name, preempt=False)
        if not ok:
            raise ValueError(message)
        run.goals.append([name, *presets[name], math.nan])

    def keep(loop, reading, voltage):
        core, now = loop.core, loop.now
        reached = core.goals.counts['reached']
        if reached and math.isnan(run.goals[reached - 1][3]):
            run.goals[reached - 1][3] = now
        state = str(core.state)
        setpoint = tuple(float(v) for v in core.last_step.setpoint[0])
        run.samples.append(Sample(
            time_s=now, measured_rad=tuple(reading.potentiometer_rad),
            true_rad=tuple(reading.true_state[:2]), setpoint_rad=setpoint,
            voltage=tuple(float(v) for v in voltage), state=state,
            measured_rad_s=tuple(reading.velocity_rad_s),
            true_rad_s=tuple(reading.true_state[2:])))
        run.scenes.append(Scene(
            joint_rad=tuple(float(v) for v in reading.true_state[:2]), state=state,
            path_rad=planner.last_path_rad, goals_xy=tuple(g.xy for g in core.pending_goals()),
            setpoint_rad=setpoint))

    loop.observers.append(keep)
    all_reached = loop.run(duration_s, lambda: loop.core.goals.counts['reached'] == len(names))
    if all_reached:
        loop.run(1.0)
    run.events = list(loop.core.events.history)
    return run


def telling_frame(run: Run) -> Scene:
    """Mid-way through the longest stretch of tracking: the arm moving along its path."""
    spans, start = [], None
    for i, scene in enumerate(run.scenes + [Scene()]):
        if scene.state == 'tracking' and start is None:
            start = i
        elif scene.state != 'tracking' and start is not None:
            spans.append((i - start, start, i))
            start = None
    if not spans:
        return run.scenes[-1]
    _, first, last = max(spans)
    return run.scenes[first + int(0.45 * (last - first))]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('output', type=Path, help='folder for the pictures')
    parser.add_argument('--params', type=Path, action='append', default=[],
                        help='parameter file layered over config/arm.yaml (repeatable)')
    parser.add_argument('--name', default='default', help='prefix of the files written')
    parser.add_argument('--goals', nargs='*', default=None, help='presets, in order')
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args(argv)
    run = closed_loop_run(args.params, args.goals, seed=args.seed)
    args.output.mkdir(parents=True, exist_ok=True)
    arm = config.load('sim', *args.params)[0]
    SceneView(arm).render_png(telling_frame(run), args.output / f'{args.name}_viewer.png')
    plot_run(Recording.from_samples(run.samples), args.output / f'{args.name}_run.png',
             title=f'{Path((args.params or ["arm.yaml"])[-1]).name}: '
                   f'{" → ".join(g[0] for g in run.goals)}',
             max_voltage=arm.battery.nominal_voltage)
    print(f'{"goal":<14} {"x (m)":>6} {"y (m)":>6} {"reached at (s)":>15}')
    for name, x, y, reached_s in run.goals:
        print(f'{name:<14} {x:6.2f} {y:6.2f} {reached_s:15.2f}')
    for event in run.events:
        if event.level != 'info':
            print(f'{event.time_s:7.2f} s {event.level}: {event}')
    print(f'wrote {args.name}_viewer.png, {args.name}_run.png in {args.output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
