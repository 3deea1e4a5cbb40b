"""The controller's own stall, or a late command, near the floor: how deep the arm goes.

A time-optimal move brakes the shoulder at its motors' current limit, so an arm that runs
ahead of its setpoint cannot be braked harder. When the controller stalls, the motors go on
with its last command (the sim does what a robot's motor controllers do), and a stall at
the moment the shoulder should switch from driving to braking leaves the arm running ahead.

In one process, in simulated time (``ClosedLoop``: the controller and the sim's plant, no
ROS): for each move, the stall (the plant keeps its last command for ``--periods`` control
periods) begins at every ``--periods``-th period of the move in turn, so that every period
of it is stalled in one run. Per move and setting, the lowest point
of either link over all those runs, and in how many runs a link went below the floor:

- as the controller runs;
- with the feedback reserve on the braking side raised by 1 V: what braking headroom buys,
  and what it costs in time.

With ``--latency``, every command of the move instead reaches the motors that many ms
late, at most a period (the one before holds meanwhile: a loaded machine's transport),
at the braking reserve the controller had before (0.5 V), at the configured one, and
0.5 V above it.

    python bench/stalls.py [--periods 2]
    python bench/stalls.py --latency 0 5 10 15 20
"""

import argparse
import dataclasses
from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


from arm_control import config  # noqa: E402
from arm_control.control.closed_loop import ClosedLoop  # noqa: E402
from arm_control.model.world import ForbiddenSpace  # noqa: E402
from arm_control.planning.planner import Planner  # noqa: E402
from arm_control.plans.goals import GoalValidator  # noqa: E402

# (name, start point, its elbow branch (index of free_configurations), goal point), in m.
MOVES = [('back -> low front, full extension', (-1.0, 1.0), 1, (1.6, 0.12)),
         ('low back -> low front', (-1.5, 0.15), 0, (1.5, 0.15)),
         ('floor -> full extension, low', (0.6, 0.1), 0, (1.75, 0.1)),
         ('low front -> far low back', (1.6, 0.1), 0, (-1.7, 0.1))]
SETTLE_S = 0.5
MOVE_LIMIT_S = 4.0


def delay_commands(plant, latency_s: float) -> None:
    """Each command reaches the plant's motors ``latency_s`` after it is sent (at most a
    period); the one before holds meanwhile."""
    set_voltage, advance = plant.set_voltage, plant.advance
    pending = []

    def arrives_later(voltage):
        pending.append(voltage)

    def advance_with_the_late_one(duration_s):
        late_s = min(latency_s, duration_s)
        advance(late_s)
        while pending:
            set_voltage(pending.pop(0))
        advance(duration_s - late_s)
    plant.set_voltage, plant.advance = arrives_later, advance_with_the_late_one


def run(arm, controller, planner, start_q, goal_xy, stall_from, periods, latency_s=0.0):
    """(lowest point of either link (m, <= 0), time to holding (s)): the plant keeps its
    last command for ``periods`` periods from the ``stall_from``-th command of the move;
    every command arrives ``latency_s`` late."""
    loop = ClosedLoop(arm, controller, planner=planner, start=tuple(start_q), seed=0)
    if latency_s > 0.0:
        delay_commands(loop.plant, latency_s)
    forbidden = ForbiddenSpace(arm)
    apply = loop.plant.set_voltage
    sent = [0]

    def maybe(voltage):
        sent[0] += 1
        if stall_from is None or not stall_from <= sent[0] < stall_from + periods:
            apply(voltage)
    loop.plant.set_voltage = maybe
    loop.run(SETTLE_S)
    began, sent[0] = loop.now, 0
    loop.core.submit_goal(loop.now, *goal_xy)
    lowest, reached = 0.0, None
    while loop.now - began < MOVE_LIMIT_S:
        loop.step()
        lowest = min(lowest, float(forbidden.lowest_point_m(loop.true_q)))
        if reached is None and str(loop.core.state) == 'holding':
            reached = loop.now - began
        if reached is not None and loop.now - began > reached + 0.5:
            break
    return lowest, reached


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--periods', type=int, default=2, help='stall length in periods')
    parser.add_argument('--latency', type=float, nargs='+', help='command latencies (ms)')
    args = parser.parse_args()
    arm, controller = config.load('controller')
    planner = Planner(arm, config.load('planner')[1])
    if args.latency:
        return latencies(arm, controller, planner, args.latency)
    settings = [('as it runs', controller),
                ('+1 V braking reserve', dataclasses.replace(
                    controller,
                    feedback_voltage_reserve=controller.feedback_voltage_reserve + 1.0))]
    print(f'A stall of {args.periods} periods ({args.periods * controller.period_s * 1000:.0f} '
          'ms), each period of the move stalled in one run; in one process, simulated time.')
    print('| move | setting | move s (no stall) | lowest mm | runs below the floor |')
    print('|---|---|---|---|---|')
    for name, start_xy, branch, goal_xy in MOVES:
        start_q = GoalValidator(arm).free_configurations(*start_xy)[branch]
        for label, settings_controller in settings:
            _, move_s = run(arm, settings_controller, planner, start_q, goal_xy, None, 0)
            periods = int(round((move_s or MOVE_LIMIT_S) / controller.period_s))
            lows = [run(arm, settings_controller, planner, start_q, goal_xy, k,
                        args.periods)[0] for k in range(1, periods + 1, args.periods)]
            below = sum(low < 0.0 for low in lows)
            print(f'| {name} | {label} | {move_s or float("nan"):.2f} | {1000 * min(lows):.0f} | '
                  f'{below} of {len(lows)} |', flush=True)


def latencies(arm, controller, planner, latencies_ms) -> None:
    print('Every command of the move late by the latency; in one process, simulated time. '
          'Each cell: the lowest point of either link (mm) / time to holding (s).')
    print('| move | braking reserve V | ' + ' | '.join(f'{ms:g} ms' for ms in latencies_ms)
          + ' |')
    print('|---|---|' + '---|' * len(latencies_ms))
    configured = controller.feedback_voltage_reserve
    for name, start_xy, branch, goal_xy in MOVES:
        start_q = GoalValidator(arm).free_configurations(*start_xy)[branch]
        for reserve_v in sorted({0.5, configured, configured + 0.5}):
            settings = dataclasses.replace(controller, feedback_voltage_reserve=reserve_v)
            cells = []
            for ms in latencies_ms:
                low, move_s = run(arm, settings, planner, start_q, goal_xy, None, 0, ms / 1000)
                cells.append(f'{1000 * low:.0f} / {move_s or float("nan"):.2f}')
            print(f'| {name} | {reserve_v:g} | ' + ' | '.join(cells) + ' |', flush=True)


if __name__ == '__main__':
    main()
