"""This controller against the seed's (GoArmSim's) control law and the minimum time, closed loop.

For each move of the trajectory benchmark's suite (``bench_trajectory.SUITE``: front to back
over the top, near full extension close to the floor, short hops, tall reaches), in
simulated time in-process on ``ArmPlant`` with sensor noise, physics on 1 ms steps:

- ours (``ArmController``): the planner's path, reshaped and timed under the motors' voltage
  (``time_optimal_trajectory``), then feedforward from the coupled inverse dynamics plus PID
  on the Kalman estimate, at 50 Hz. Planning runs the moment the goal arrives (in the control
  cycle the goal arrives in) and the plan is applied as soon as it is ready: the loop runs an
  extra control cycle then, so the arm waits exactly the planning time -- measured as this
  process's CPU time for path + timing, the arm holding its old voltage meanwhile;
- the seed's law: two independent loops on the potentiometers, errors in radians,
  V = 12·clamp(kP·e + kD·Δe, −1, 1) + m·g·(L/2)·cos θ in volts (an uncoupled rod per link,
  θ the link's own heading), shoulder kP 2.00 kD 0.04, elbow kP 1.75 kD 0.02, the elbow
  branch by the seed's quadrant rule (elbow negative for x ≥ 0, positive for x < 0), 50 Hz;
- the minimum (``--minimum``): direct collocation (casadi + IPOPT, ``minimum_time``) with
  the knot count refined 25 → 50 → 100, on every free elbow branch of the goal, the least
  kept: the fastest any controller could go under the sim's electrical limits (current
  limits, bus sag, brownout) and the floor; and the least whole number of 20 ms periods of
  constant voltage, within those limits, that bring the arm from rest to rest ("50 Hz
  min"): what holding each command for a 50 Hz period alone costs.

Each move starts from rest, held for 0.5 s; the goal is given at t = 0. Measured on the
true state every 1 ms: move time (from the goal to within goal_tolerance_rad on both joints
and slower than settled_velocity_rad_s, for good), final error (1 s after that), overshoot
(how far a joint goes past the goal, in the direction it was moving, after both first
get within tolerance), peak |voltage|,
the lowest point of the elbow or the tool (below 0: floor contact), and from the plant's
electrical model: the lowest bus voltage, the peak motor current, the energy drawn from the
battery over the move (∫ V_bus·I_supply dt from the goal to the arrival; regeneration
counts against it) and any brownout. Then the cost of
latency: ours with the plan taken only at the next regular 50 Hz tick, and at 200 Hz.

    python bench/bench_controller.py                 # the suite, side by side
    python bench/bench_controller.py --minimum       # ... and the minimum times (slow)
    python bench/bench_controller.py --moves 4,5     # some moves only
    python bench/bench_controller.py --set feedback_voltage_reserve=0.5   # a what-if
"""

from dataclasses import replace
import json
import math
from pathlib import Path
import statistics
import sys

BENCH = Path(__file__).resolve().parent
sys.path[:0] = [str(BENCH), str(BENCH.parent)]       # the suite beside, the package above

from bench_trajectory import _start_configuration, Move, SUITE  # noqa: E402 (one suite)
from in_process import fmt, measure, Run, run_ours, simulate, TIMEOUT_S  # noqa: E402
import minimum_time as ocp  # noqa: E402
import numpy as np  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.model.dynamics import ArmDynamics  # noqa: E402
from arm_control.model.kinematics import TwoLinkKinematics  # noqa: E402
from arm_control.model.world import ForbiddenSpace  # noqa: E402
from arm_control.planning.planner import Planner  # noqa: E402

SEED_GAINS = ((2.00, 0.04), (1.75, 0.02))       # (kP, kD) shoulder, elbow
SEED_RATE_HZ = 50.0
ZOH_PERIOD_S = 0.02


class SeedController:
    """GoArmSim's law: per joint 12·clamp(kP·e + kD·Δe, −1, 1) + an uncoupled gravity term."""

    def __init__(self, arm, goal_q):
        self.arm = arm
        self.goal_q = np.array(goal_q, float)
        self.motors = ArmDynamics(arm).motors
        self.previous_error = None

    @staticmethod
    def goal_for(kinematics, x, y):
        """The quadrant rule: elbow negative in front (x ≥ 0), positive behind."""
        positive, negative = kinematics.inverse(x, y)
        return negative if x >= 0.0 else positive

    def step(self, now_s, reading):
        error = self.goal_q - np.asarray(reading.potentiometer_rad, float)
        change = np.zeros(2) if self.previous_error is None else error - self.previous_error
        self.previous_error = error
        voltage = []
        headings = (reading.potentiometer_rad[0],
                    reading.potentiometer_rad[0] + reading.potentiometer_rad[1])
        for k, ((kp, kd), joint, motor, heading) in enumerate(
                zip(SEED_GAINS, self.arm.joints, self.motors, headings)):
            feedback = 12.0 * min(max(kp * error[k] + kd * change[k], -1.0), 1.0)
            rod_torque = joint.mass_kg * self.arm.gravity_mps2 * joint.length_m / 2 \
                * math.cos(heading)
            voltage.append(feedback + motor.voltage_for(rod_torque, 0.0))
        volts = self.arm.battery.nominal_voltage
        return np.clip(voltage, -volts, volts)


def run_seed(arm, controller_config, start_q, goal_xy, seed):
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    goal_q = np.array(SeedController.goal_for(kinematics, *goal_xy))
    seed_controller = SeedController(arm, start_q)

    def give_goal(t):
        seed_controller.goal_q = goal_q
        seed_controller.previous_error = None

    seed_config = replace(controller_config, loop_rate_hz=SEED_RATE_HZ)
    record = simulate(arm, seed_config, seed_controller, give_goal, start_q, seed)
    return measure(arm, seed_config, record, goal_q, start_q)


# --- the table --------------------------------------------------------------------------

def parse(argv):
    options = {'minimum': '--minimum' in argv, 'moves': None, 'set': {}, 'cache': ocp.CACHE,
               'latency': '--no-latency' not in argv, 'seed': '--no-seed' not in argv}
    for flag, value in zip(argv, argv[1:] + ['']):
        if flag == '--moves':
            options['moves'] = [int(i) for i in value.split(',')]
        elif flag == '--set':
            name, text = value.split('=', 1)
            options['set'][name] = json.loads(text)
        elif flag == '--minimum-cache':
            options['cache'], options['minimum'] = value, True
    return options


def main(argv):
    options = parse(argv)
    arm, controller_config = config.load('controller')
    if options['set']:
        controller_config = replace(controller_config, **{
            name: tuple(value) if isinstance(value, list) else value
            for name, value in options['set'].items()})
    planner = Planner(arm, config.load('planner')[1])
    forbidden = ForbiddenSpace(arm)
    moves = [SUITE[i] for i in options['moves']] if options['moves'] else SUITE
    rows = []
    # A warm-up, as the nodes' worker does before it is ready: the first timing in a process
    # loads the compiled kernels (0.1-0.2 s), which the first move would wait for.
    name, start_xy, goal_xy = moves[0]
    first = Move(name, start_xy, goal_xy, arm, controller_config, None, forbidden, None)
    run_ours(arm, controller_config, planner, _start_configuration(first), goal_xy, seed=0)
    for name, start_xy, goal_xy in moves:
        index = SUITE.index((name, start_xy, goal_xy))
        move = Move(name, start_xy, goal_xy, arm, controller_config, None, forbidden, None)
        start_q = _start_configuration(move)
        ours = run_ours(arm, controller_config, planner, start_q, goal_xy, seed=index)
        seed_run = (run_seed(arm, controller_config, start_q, goal_xy, seed=index)
                    if options['seed'] else Run())
        variants = []
        if options['latency']:
            variants.append(run_ours(arm, controller_config, planner, start_q, goal_xy,
                                     seed=index, at_next_tick=True))
            variants.append(run_ours(arm, replace(controller_config, loop_rate_hz=200.0),
                                     planner, start_q, goal_xy, seed=index))
        rows.append((name, ours, seed_run, variants))
        print(f'  {name}: ours {fmt(ours.move_s, ".3f")} s (plan {ours.plan_cpu_ms:.1f} ms '
              f'+ trajectory {ours.trajectory_s:.3f} s), seed {fmt(seed_run.move_s)} s',
              file=sys.stderr, flush=True)
    # Last: IPOPT leaves threads behind that would disturb the timings above.
    starts = [(name, _start_configuration(
        Move(name, start_xy, goal_xy, arm, None, None, forbidden, None)), goal_xy)
        for name, start_xy, goal_xy in moves]
    minimum = (ocp.suite_minimums(arm, controller_config, starts, options['cache'],
                                  ZOH_PERIOD_S) if options['minimum'] else {})

    rate = controller_config.loop_rate_hz
    print(f'Moves on the default arm, {rate:g} Hz, sensor noise on; times from the goal to '
          f'within {math.degrees(controller_config.goal_tolerance_rad):.1f} deg and slower '
          f'than {controller_config.settled_velocity_rad_s:g} rad/s for good (true state, '
          f'1 ms); "n/a" = not there by {TIMEOUT_S:g} s. "plan ms": path + timing, CPU '
          '(wall); "traj s": the trajectory\'s duration.')
    header = ['move', 'ours s', 'seed s']
    if minimum:
        header += ['min s', '50 Hz min s', 'ours/min', 'traj/min']
    header += ['traj s', 'plan ms', 'final err deg ours/seed', 'overshoot deg ours/seed',
               'peak V ours/seed', 'lowest mm ours/seed', 'min bus V ours/seed',
               'peak A ours/seed', 'energy J ours/seed', 'brownouts ours/seed']
    print('| ' + ' | '.join(header) + ' |')
    print('|' + '---|' * len(header))
    for name, ours, seed_run, _ in rows:
        cells = [name, fmt(ours.move_s, '.3f'), fmt(seed_run.move_s)]
        if minimum:
            best = minimum.get(name, {}).get('min_s', math.nan)
            cells += [fmt(best, '.3f'), fmt(minimum.get(name, {}).get('zoh_s', math.nan)),
                      fmt(ours.move_s / best), fmt(ours.trajectory_s / best)]
        cells += [fmt(ours.trajectory_s, '.3f'),
                  f'{ours.plan_cpu_ms:.1f} ({ours.plan_wall_ms:.0f})',
                  f'{fmt(ours.final_error_deg)} / {fmt(seed_run.final_error_deg)}',
                  f'{fmt(ours.overshoot_deg)} / {fmt(seed_run.overshoot_deg)}',
                  f'{ours.peak_voltage:.1f} / {fmt(seed_run.peak_voltage, ".1f")}',
                  f'{1000 * ours.lowest_m:.0f} / {fmt(1000 * seed_run.lowest_m, ".0f")}',
                  f'{fmt(ours.min_bus_v)} / {fmt(seed_run.min_bus_v)}',
                  f'{fmt(ours.peak_current_a, ".0f")} / {fmt(seed_run.peak_current_a, ".0f")}',
                  f'{fmt(ours.energy_j, ".0f")} / {fmt(seed_run.energy_j, ".0f")}',
                  f'{ours.brownouts} / {seed_run.brownouts}']
        print('| ' + ' | '.join(cells) + ' |')

    reached = [r for _, r, _, _ in rows if r.reached]
    seed_reached = [s for _, _, s, _ in rows if s.reached]
    print(f'\nreached: ours {len(reached)}/{len(rows)}, seed {len(seed_reached)}/{len(rows)}; '
          f'floor contact (lowest < 0): ours {sum(r.lowest_m < 0 for _, r, _, _ in rows)}, '
          f'seed {sum(s.lowest_m < 0 for _, _, s, _ in rows)}')
    if reached:
        print(f'ours: worst final error {max(r.final_error_deg for r in reached):.2f} deg, '
              f'worst overshoot {max(r.overshoot_deg for r in reached):.2f} deg')
    if minimum:
        ratios = [r.move_s / minimum[n]['min_s'] for n, r, _, _ in rows
                  if n in minimum and r.reached]
        if ratios:
            print(f'ours/min: median {statistics.median(ratios):.2f}, worst {max(ratios):.2f}; '
                  f'within 1.15: {sum(r <= 1.15 for r in ratios)}/{len(rows)}')
    plan_cpu = [r.plan_cpu_ms for _, r, _, _ in rows]
    plan_wall = [r.plan_wall_ms for _, r, _, _ in rows]
    print(f'planning per goal (path for each free branch + reshaping + timing): CPU median '
          f'{statistics.median(plan_cpu):.1f} ms, worst {max(plan_cpu):.1f} ms; wall median '
          f'{statistics.median(plan_wall):.1f} ms, worst {max(plan_wall):.1f} ms')
    cycles = np.concatenate([r.cycle_cpu_ms for _, r, _, _ in rows])
    print(f'CPU per control cycle (estimator + state machine + period feedforward + PID; '
          f'planning apart): median {np.median(cycles):.2f} ms, p99 '
          f'{np.percentile(cycles, 99):.2f} ms of the {1000 / rate:g} ms period')
    if minimum:
        print(f'\nMinimum time (direct collocation under the electrical limits, least over the '
              f'free elbow branches) as the knots are refined {ocp.KNOTS}:')
        for name, _, _, _ in rows:
            knots = minimum.get(name, {}).get('knots_s', [])
            change = (abs(knots[-1] - knots[-2]) / knots[-1] if len(knots) > 1 else math.nan)
            print(f'  {name}: {", ".join(fmt(t, ".4f") for t in knots)} s '
                  f'(last change {fmt(100 * change, ".2f")} %)')
    if options['latency']:
        print('\nWhat latency costs (move time s): ours as above | the plan taken only at the '
              'next regular 50 Hz tick | ours with a 200 Hz loop')
        print('| move | ours s | next tick s | 200 Hz s |'
              + (' 200 Hz/min |' if minimum else ''))
        print('|---|---|---|---|' + ('---|' if minimum else ''))
        for name, ours, _, (late, fast) in rows:
            cells = [name, fmt(ours.move_s, '.3f'), fmt(late.move_s, '.3f'),
                     fmt(fast.move_s, '.3f')]
            if minimum:
                cells.append(fmt(fast.move_s / minimum.get(name, {}).get('min_s', math.nan)))
            print('| ' + ' | '.join(cells) + ' |')


if __name__ == '__main__':
    main(sys.argv[1:])
