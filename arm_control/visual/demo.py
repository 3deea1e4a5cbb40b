"""A real closed-loop run without ROS, recorded, plotted and drawn: the README's pictures.

The controller core, the planner and the simulated arm run in one process, in simulated
time, at the controller's loop rate: each period the plant's sensor reading goes to
``ArmController.step`` and the voltage it returns drives ``ArmPlant``. Every period is kept
as a ``Sample`` (for ``plots.plot_run``) and as a ``Scene`` (for the viewer's picture).

    python -m arm_control.visual.demo docs/                          # the default arm
    python -m arm_control.visual.demo docs/ --params config/frc_robot.yaml --name frc_robot

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
from arm_control.control.arm_controller import ArmController
from arm_control.model.plant import ArmPlant
from arm_control.planning.planner import Planner
from arm_control.visual.plots import plot_run
from arm_control.visual.recording import Recording, Sample
from arm_control.visual.scene import Scene, SceneView


class PlannerTap:
    """The planner, passed through, keeping the last path it returned (for the picture)."""

    def __init__(self, planner):
        self.planner = planner
        self.last_path_rad: tuple = ()

    def plan(self, start_q, goal_xy):
        plan = self.planner.plan(start_q, goal_xy)
        if plan.ok:
            self.last_path_rad = tuple(map(tuple, np.asarray(plan.waypoints_rad)))
        return plan


@dataclass
class Run:
    samples: list = field(default_factory=list)         # Sample per control period
    scenes: list = field(default_factory=list)          # Scene per control period
    goals: list = field(default_factory=list)           # (label, x, y, reached at s or nan)
    events: list = field(default_factory=list)          # the controller's Event list


def closed_loop_run(params_file, goal_names=None, duration_s: float = 30.0,
                    seed: int = 0) -> Run:
    """Send the presets ``goal_names`` (default: every preset) at t = 0, queued, and run
    until all are reached and 1 s more, or ``duration_s``."""
    arm, sim_config = config.load('sim', params_file)
    controller_config = config.load('controller', params_file)[1]
    planner_config = config.load('planner', params_file)[1]
    planner = PlannerTap(Planner(arm, planner_config))
    plant = ArmPlant(arm, sim_config.initial_position, sim_config.physics_step_s, seed)
    core = ArmController(arm, controller_config, planner)
    period_s = 1.0 / controller_config.loop_rate_hz
    presets = {name: (x, y) for name, x, y in arm.presets}
    names = list(goal_names or presets)
    run = Run()
    for name in names:
        ok, message = core.submit_preset(0.0, name, preempt=False)
        if not ok:
            raise ValueError(message)
        run.goals.append([name, *presets[name], math.nan])
    end_s = duration_s
    while plant.time_s < end_s:
        now = plant.time_s
        reading = plant.read()
        reached_before = core.counts['reached']
        voltage = core.step(now, reading)
        if core.counts['reached'] > reached_before:
            run.goals[reached_before][3] = now
            if core.counts['reached'] == len(names):
                end_s = min(end_s, now + 1.0)
        plant.set_voltage(voltage)
        state = str(core.state)
        setpoint = tuple(float(v) for v in core.setpoint[0])
        run.samples.append(Sample(
            time_s=now, measured_rad=tuple(reading.potentiometer_rad),
            true_rad=tuple(reading.true_state[:2]), setpoint_rad=setpoint,
            voltage=tuple(float(v) for v in voltage), state=state,
            measured_rad_s=tuple(reading.velocity_rad_s),
            true_rad_s=tuple(reading.true_state[2:])))
        waiting = ([core.current_goal] if core.current_goal is not None else []) \
            + list(core.queue)
        run.scenes.append(Scene(
            joint_rad=tuple(float(v) for v in reading.true_state[:2]), state=state,
            path_rad=planner.last_path_rad, goals_xy=tuple(g.xy for g in waiting),
            setpoint_rad=setpoint))
        plant.advance(period_s)
    run.events = list(core.events)
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
    parser.add_argument('--params', type=Path, default=None,
                        help='parameter file (default: the installed config/arm.yaml)')
    parser.add_argument('--name', default='default', help='prefix of the files written')
    parser.add_argument('--goals', nargs='*', default=None, help='presets, in order')
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args(argv)
    params_file = args.params or config.default_parameter_file()
    run = closed_loop_run(params_file, args.goals, seed=args.seed)
    args.output.mkdir(parents=True, exist_ok=True)
    arm = config.load('sim', params_file)[0]
    SceneView(arm).render_png(telling_frame(run), args.output / f'{args.name}_viewer.png')
    plot_run(Recording.from_samples(run.samples), args.output / f'{args.name}_run.png',
             title=f'{Path(params_file).name}: {" → ".join(g[0] for g in run.goals)}',
             max_voltage=arm.max_voltage)
    print(f'{"goal":<14} {"x (m)":>6} {"y (m)":>6} {"reached at (s)":>15}')
    for name, x, y, reached_s in run.goals:
        print(f'{name:<14} {x:6.2f} {y:6.2f} {reached_s:15.2f}')
    for event in run.events:
        if event.level != 'info':
            print(f'{event.time_s:7.2f} s {event.level}: {event.message}')
    print(f'wrote {args.name}_viewer.png, {args.name}_run.png in {args.output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
