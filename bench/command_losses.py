"""The controller's commands lost mid-move: does the arm get its goal, out of the floor?

A DDS write blocks for about 330 ms now and then when a node joins the graph
(``dds_write_block.py``); when it is the controller's, the sim, as a motor controller does,
applies 0 V once no command has come for ``command_timeout_s`` -- while the controller runs
on, not knowing. In one process (the core and the plant, no ROS): for three moves, the plant
gets 0 V for 0.3 or 0.5 s from each of several moments of the move (s after it began), while
the core's commands are thrown away; then the run goes on for 4 s. Per run: the state at the
end, whether the goal was reached, and the lowest point of either link (mm; below 0 is in
the floor).

    python bench/command_losses.py
"""

from pathlib import Path
import sys

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / 'test' / 'rigs'), str(HERE.parent)]

from bench_ros import lowest_mm  # noqa: E402
from controller_rig import run, START  # noqa: E402
import numpy as np  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.control.controller import ArmController  # noqa: E402
from arm_control.control.state_machine import ArmState  # noqa: E402
from arm_control.model.plant import ArmPlant  # noqa: E402
from arm_control.planning.planner import Planner  # noqa: E402
from arm_control.plans.port import plan_in_process  # noqa: E402

MOVES = (('mid -> high back', (1.1, 0.9), (-0.6, 1.5)),
         ('low back -> low front', (-1.5, 0.15), (1.6, 0.1)),
         ('mid -> back (over the top)', (1.1, 0.9), (-1.0, 1.0)))
MOMENTS_S = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.7)
LOSSES_S = (0.3, 0.5)


def one_run(arm, controller, planner_config, start_xy, goal_xy, into_s, lost_s):
    core = plan_in_process(ArmController(arm, controller), Planner(arm, planner_config))
    plant = ArmPlant(arm, START, seed=6)
    period_s = 1.0 / controller.loop_rate_hz
    core.submit_goal(plant.time_s, *start_xy)
    run(core, plant, 5.0, period_s, until=lambda: core.state == ArmState.HOLDING)
    run(core, plant, 1.0, period_s)
    core.submit_goal(plant.time_s, *goal_xy)
    run(core, plant, 2.0, period_s, until=lambda: core.state == ArmState.TRACKING)
    run(core, plant, into_s, period_s)
    core.events.take()
    q = []
    for step in range(round(4.0 / period_s)):
        voltage = core.step(plant.time_s, plant.read()).volts
        plant.set_voltage(np.zeros(2) if step < round(lost_s / period_s) else voltage)
        plant.advance(period_s)
        q.append(plant.state[:2])
    kinds = [event.kind.value for event in core.events.take()]
    return core.state, 'goal_reached' in kinds, 'off_plan' in kinds, lowest_mm(arm, np.array(q))


def main() -> None:
    arm, controller = config.load('controller')
    planner_config = config.load('planner')[1]
    print('| move | lost at s | lost for s | state at the end | reached | left its plan | '
          'lowest mm |')
    print('|---|---|---|---|---|---|---|')
    bad = runs = 0
    for name, start_xy, goal_xy in MOVES:
        for into_s in MOMENTS_S:
            for lost_s in LOSSES_S:
                state, reached, left, lowest = one_run(arm, controller, planner_config,
                                                       start_xy, goal_xy, into_s, lost_s)
                runs += 1
                bad += not reached or lowest < 0.0
                print(f'| {name} | {into_s:.1f} | {lost_s:.1f} | {state} | '
                      f'{"yes" if reached else "no"} | {"yes" if left else "no"} | '
                      f'{lowest:.0f} |', flush=True)
    print(f'\n{bad} of {runs} runs missed the goal or touched the floor.')


if __name__ == '__main__':
    main()
