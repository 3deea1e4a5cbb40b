"""This controller against the seed's (GoArmSim's) control law, on the same coupled plant.

For each move of the trajectory benchmark's suite (``bench_trajectory.SUITE``: front to back
over the top, near full extension close to the floor, short hops, tall reaches), in
simulated time in-process on ``ArmPlant`` with sensor noise:

- this controller (``ArmController``): the planner's path, timed by TOPP-RA within 11 V, then
  feedforward from the coupled inverse dynamics at the setpoint plus PID on the Kalman
  estimate, at 50 Hz. The plan arrives as late as computing it took (path plus timing,
  measured on this machine, rounded up to whole control periods), as it would in the node;
- the seed's law: two independent loops on the potentiometers, errors in radians,
  V = 12·clamp(kP·e + kD·Δe, −1, 1) + m·g·(L/2)·cos θ in volts (an uncoupled rod per link,
  θ the link's own heading), shoulder kP 2.00 kD 0.04, elbow kP 1.75 kD 0.02, the elbow
  branch by the seed's quadrant rule (elbow negative for x ≥ 0, positive for x < 0), 50 Hz.

Each move starts from rest, held for 0.5 s; the goal is given at t = 0. Measured on the
true state: move time (from the goal to within 1 deg on both joints and still -- slower
than 0.05 rad/s -- for good), final error (1 s after that), overshoot (how far a joint goes
past the goal after first reaching it), peak |voltage|, and the lowest height of the elbow
or the tool (below 0: floor contact). Then this controller's compute per control cycle
(CPU time: median, 99th percentile; planning excluded, it runs off the loop in the node),
planning per goal (wall time), and closed-loop runs at higher loop rates.

    python bench/bench_controller.py             # the suite, side by side
    python bench/bench_controller.py --minimum   # ... and the direct-collocation minimum
                                                 #     time of each move (slow: casadi)
"""

from dataclasses import dataclass, replace
import math
from pathlib import Path
import statistics
import sys
import time

import numpy as np

BENCH = Path(__file__).resolve().parent
sys.path[:0] = [str(BENCH), str(BENCH.parent)]       # the suite beside, the package above

from bench_trajectory import _start_configuration, Move, SUITE  # noqa: E402 (one suite)

from arm_control import config  # noqa: E402
from arm_control.control.arm_controller import ArmController  # noqa: E402
from arm_control.control.trajectory import TrajectoryLimits  # noqa: E402
from arm_control.model.dynamics import ArmDynamics  # noqa: E402
from arm_control.model.kinematics import TwoLinkKinematics  # noqa: E402
from arm_control.model.plant import ArmPlant  # noqa: E402
from arm_control.planning.cspace import ForbiddenSpace  # noqa: E402
from arm_control.planning.planner import Planner  # noqa: E402

HOLD_BEFORE_S = 0.5
TIMEOUT_S = 8.0
FINAL_AFTER_S = 1.0
SEED_GAINS = ((2.00, 0.04), (1.75, 0.02))       # (kP, kD) shoulder, elbow
SEED_RATE_HZ = 50.0


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
        return np.clip(voltage, -self.arm.max_voltage, self.arm.max_voltage)


class LatePlanner:
    """The core's planner hand-off, answered as late as computing the answer took."""

    def __init__(self, core, planner, period_s):
        self.core, self.planner, self.period_s = core, planner, period_s
        self.waiting = []             # (deliver at, timed plan)
        self.plan_s = []
        self.delivered_s = math.nan

    def step(self, now_s):
        for request in self.core.take_plan_requests():
            timed = self.core.plan_directly(request, self.planner)
            self.plan_s.append(timed.compute_s)
            delay = math.ceil(timed.compute_s / self.period_s) * self.period_s
            self.waiting.append((now_s + delay, timed))
        for item in list(self.waiting):
            if item[0] <= now_s + 1e-9:
                self.waiting.remove(item)
                self.core.on_timed_plan(now_s, item[1])
                self.delivered_s = now_s


@dataclass
class Run:
    """What one controller did on one move, measured on the true state."""

    move_s: float = math.nan
    final_error_deg: float = math.nan
    overshoot_deg: float = 0.0
    peak_voltage: float = 0.0
    lowest_m: float = math.inf
    reached: bool = False
    plan_arrived_s: float = math.nan     # ours: when the timed plan was taken
    trajectory_s: float = math.nan       # ours: how long its trajectory lasts


def heights_m(arm, q):
    """min(y of the elbow, y of the tool): the lowest point of the links above the pivot."""
    elbow_y = arm.shoulder.length_m * math.sin(q[0])
    return min(elbow_y, elbow_y + arm.elbow.length_m * math.sin(q[0] + q[1]))


def measure(arm, controller_config, times, states, voltages, goal_q, start_q) -> Run:
    """Move time, final error, overshoot, peak voltage and lowest point of a recorded run."""
    tolerance = controller_config.goal_tolerance_rad
    still_below = controller_config.settled_velocity_rad_s
    times, states, voltages = np.array(times), np.array(states), np.array(voltages)
    after = times >= 0.0
    t, x, v = times[after], states[after], voltages[after]
    error = np.abs(x[:, :2] - goal_q)
    inside = np.all(error < tolerance, axis=1)
    still = np.all(np.abs(x[:, 2:]) < still_below, axis=1)
    run = Run(peak_voltage=float(np.max(np.abs(v))),
              lowest_m=min(heights_m(arm, q) for q in x[:, :2]))
    # Settled: inside from here to the end, and still at that moment.
    outside_after = np.flatnonzero(~inside)
    first_for_good = 0 if len(outside_after) == 0 else outside_after[-1] + 1
    candidates = [i for i in range(first_for_good, len(t)) if still[i]]
    if candidates and t[-1] - t[candidates[0]] >= FINAL_AFTER_S - 1e-9:
        i = candidates[0]
        run.move_s, run.reached = float(t[i]), True
        j = int(np.searchsorted(t, t[i] + FINAL_AFTER_S))
        run.final_error_deg = float(np.degrees(np.max(error[min(j, len(t) - 1)])))
    else:
        run.final_error_deg = float(np.degrees(np.max(error[-1])))
    for k in range(2):                  # past the goal after first getting within tolerance
        first = np.flatnonzero(error[:, k] < tolerance)
        if len(first):
            direction = np.sign(goal_q[k] - start_q[k]) or 1.0
            past = direction * (x[first[0]:, k] - goal_q[k])
            run.overshoot_deg = max(run.overshoot_deg, float(np.degrees(max(past.max(), 0.0))))
    return run


def simulate(arm, controller_config, make, start_q, seed):
    """Hold at the start, give the goal at t = 0, run until settled for 1 s or timed out."""
    plant = ArmPlant(arm, start_q, seed=seed)
    period = 1.0 / controller_config.loop_rate_hz
    controller, on_goal, extra = make(period)
    times, states, voltages, compute = [], [], [], []
    t = -HOLD_BEFORE_S
    goal_given = False
    while t < TIMEOUT_S:
        if not goal_given and t >= -1e-9:
            on_goal(t)
            goal_given = True
        reading = plant.read()
        began = time.thread_time()          # CPU time: what a cycle costs, whoever else runs
        voltage = controller.step(t, reading)
        compute.append(time.thread_time() - began)
        if extra is not None:
            extra(t)
        plant.set_voltage(voltage)
        times.append(t)
        states.append(np.array(plant.state))
        voltages.append(np.array(voltage))
        plant.advance(period)
        t += period
        if goal_given and len(times) > 10 and t > 0.5 and _settled_for(
                controller_config, times, states, voltages, FINAL_AFTER_S + 0.1):
            break
    return times, states, voltages, compute


def _settled_for(controller_config, times, states, voltages, span_s):
    """Stop early once the arm has been still for ``span_s`` (measure() decides the rest)."""
    count = int(span_s * controller_config.loop_rate_hz)
    recent = np.array(states[-count:])
    return len(recent) == count and np.all(np.abs(recent[:, 2:])
                                           < controller_config.settled_velocity_rad_s) \
        and np.ptp(recent[:, 0]) < 1e-3 and np.ptp(recent[:, 1]) < 1e-3


def run_ours(arm, controller_config, planner, start_q, goal_xy, seed):
    state = {}

    def make(period):
        core = ArmController(arm, controller_config)
        late = LatePlanner(core, planner, period)
        state.update(core=core, late=late)
        return core, lambda t: core.submit_goal(t, *goal_xy), late.step

    times, states, voltages, compute = simulate(arm, controller_config, make, start_q, seed)
    core = state['core']
    goal_q = core.goal_q if core.goal_q is not None else np.full(2, np.nan)
    run = measure(arm, controller_config, times, states, voltages, goal_q, start_q)
    if core.last_timed_plan is not None and core.last_timed_plan.ok:
        run.trajectory_s = core.last_timed_plan.trajectory.duration_s
        run.plan_arrived_s = state['late'].delivered_s
    return run, compute, state['late'].plan_s


def run_seed(arm, controller_config, start_q, goal_xy, seed):
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    goal_q = np.array(SeedController.goal_for(kinematics, *goal_xy))
    holder = {}

    def make(period):
        seed_controller = SeedController(arm, start_q)
        holder['c'] = seed_controller

        def give_goal(t):
            seed_controller.goal_q = goal_q
            seed_controller.previous_error = None
        return seed_controller, give_goal, None

    seed_config = replace(controller_config, loop_rate_hz=SEED_RATE_HZ)
    times, states, voltages, _ = simulate(arm, seed_config, make, start_q, seed)
    return measure(arm, seed_config, times, states, voltages, goal_q, start_q)


def fmt(value, spec='.2f'):
    return 'n/a' if value is None or not math.isfinite(value) else format(value, spec)


def minimum_times(arm, controller_config):
    """The direct-collocation minimum time of each move, from the trajectory benchmark."""
    import bench_trajectory as bt
    dynamics, forbidden = ArmDynamics(arm), ForbiddenSpace(arm)
    limits = TrajectoryLimits.from_config(arm, controller_config)
    out = {}
    for name, start_xy, goal_xy in SUITE:
        move = Move(name, start_xy, goal_xy, arm, controller_config, dynamics, forbidden, limits)
        bt.plan_path(move)
        bt.column_toppra(move)
        bt.column_toppra_full_voltage(move)
        bt.column_minimum_time(move)
        out[name] = move.results['minimum_s']
        print(f'  minimum time {name}: {out[name]:.3f} s', file=sys.stderr, flush=True)
    return out


def main(argv):
    arm, controller_config = config.load('controller')
    planner = Planner(arm, config.load('planner')[1])
    forbidden = ForbiddenSpace(arm)
    rows, compute_all, plan_all = [], [], []
    for index, (name, start_xy, goal_xy) in enumerate(SUITE):
        move = Move(name, start_xy, goal_xy, arm, controller_config, None, forbidden, None)
        start_q = _start_configuration(move)
        ours, compute, plan_s = run_ours(arm, controller_config, planner, start_q, goal_xy,
                                         seed=index)
        compute_all += compute
        plan_all += plan_s
        seed_run = run_seed(arm, controller_config, start_q, goal_xy, seed=index)
        rows.append((name, ours, seed_run))
        print(f'  {name}: ours {fmt(ours.move_s)} s, seed {fmt(seed_run.move_s)} s',
              file=sys.stderr, flush=True)
    rates = []
    for rate in (100.0, 200.0, 500.0):
        fast = replace(controller_config, loop_rate_hz=rate)
        times_s, errors, cycle = [], [], []
        for index, (name, start_xy, goal_xy) in enumerate(SUITE[:6]):
            move = Move(name, start_xy, goal_xy, arm, fast, None, forbidden, None)
            run, compute, _ = run_ours(arm, fast, planner, _start_configuration(move),
                                       goal_xy, seed=index)
            times_s.append(run.move_s)
            errors.append(run.final_error_deg)
            cycle += compute
        rates.append((rate, times_s, errors, 1000 * np.percentile(cycle, 99)))
    # Last: IPOPT leaves threads behind that would disturb the timings above.
    minimum = minimum_times(arm, controller_config) if '--minimum' in argv else {}

    print(f'Moves on the default arm, {controller_config.loop_rate_hz:g} Hz, sensor noise on; '
          'times from the goal to within 1 deg and still (true state); "n/a" = not within '
          f'tolerance and still by {TIMEOUT_S:g} s. "plan + traj s": when the plan arrived '
          'and how long its trajectory lasts.')
    header = ['move', 'ours s', 'plan + traj s', 'seed s']
    if minimum:
        header += ['min s', 'ours/min', 'traj/min']
    header += ['final err deg ours/seed', 'overshoot deg ours/seed', 'peak V ours/seed',
               'lowest mm ours/seed']
    print('| ' + ' | '.join(header) + ' |')
    print('|' + '---|' * len(header))
    for name, ours, seed_run in rows:
        cells = [name, fmt(ours.move_s), f'{ours.plan_arrived_s:.2f} + {ours.trajectory_s:.3f}',
                 fmt(seed_run.move_s)]
        if minimum:
            best = minimum.get(name, math.nan)
            cells += [fmt(best, '.3f'), fmt(ours.move_s / best, '.2f'),
                      fmt(ours.trajectory_s / best, '.2f')]
        cells += [f'{fmt(ours.final_error_deg)} / {fmt(seed_run.final_error_deg)}',
                  f'{fmt(ours.overshoot_deg)} / {fmt(seed_run.overshoot_deg)}',
                  f'{ours.peak_voltage:.1f} / {seed_run.peak_voltage:.1f}',
                  f'{1000 * ours.lowest_m:.0f} / {1000 * seed_run.lowest_m:.0f}']
        print('| ' + ' | '.join(cells) + ' |')
    reached = [r for _, r, _ in rows if r.reached]
    seed_reached = [s for _, _, s in rows if s.reached]
    print(f'\nreached: ours {len(reached)}/{len(rows)}, seed {len(seed_reached)}/{len(rows)}; '
          f'floor contact (lowest < 0): ours {sum(r.lowest_m < 0 for _, r, _ in rows)}, '
          f'seed {sum(s.lowest_m < 0 for _, _, s in rows)}')
    if reached:
        after = sum(r.move_s - r.plan_arrived_s - r.trajectory_s for r in reached)
        print(f'ours: worst final error {max(r.final_error_deg for r in reached):.2f} deg, '
              f'total move time {sum(r.move_s for r in reached):.2f} s, of which after the '
              f'trajectories ended {after:.2f} s')
    compute_ms = 1000 * np.array(compute_all)
    median, p99 = np.median(compute_ms), np.percentile(compute_ms, 99)
    print(f'\nCPU per control cycle (estimator + state machine + feedforward + PID; the '
          f'plan arrives off-loop): median {median:.3f} ms, p99 {p99:.3f} ms, worst '
          f'{compute_ms.max():.3f} ms over {len(compute_ms)} cycles -> sustains about '
          f'{1000 / p99:.0f} Hz on this machine (1 / p99)')
    plan_ms = 1000 * np.array(plan_all)
    print(f'planning per goal (path + branch choice by trajectory time + TOPP-RA timing, '
          f'wall): median {np.median(plan_ms):.1f} ms, worst {plan_ms.max():.1f} ms')
    print('\nHigher loop rates, the first 6 moves (ours):')
    for rate, times_s, errors, cycle_p99 in rates:
        print(f'  {rate:5.0f} Hz: move time median {fmt(statistics.median(times_s))} s, '
              f'worst final error {fmt(max(errors))} deg, CPU p99 {cycle_p99:.3f} ms of a '
              f'{1000 / rate:.1f} ms period, reached {sum(math.isfinite(t) for t in times_s)}'
              f'/{len(times_s)}')


if __name__ == '__main__':
    main(sys.argv[1:])
