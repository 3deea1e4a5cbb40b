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

from dataclasses import dataclass, replace
import json
import math
from pathlib import Path
import statistics
import sys
import time

BENCH = Path(__file__).resolve().parent
sys.path[:0] = [str(BENCH), str(BENCH.parent)]       # the suite beside, the package above

from bench_trajectory import _start_configuration, Move, SUITE  # noqa: E402 (one suite)
import minimum_time as ocp  # noqa: E402
import numpy as np  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.control.controller import ArmController  # noqa: E402
from arm_control.control.goals import GoalValidator  # noqa: E402
from arm_control.control.trajectory import (time_optimal_trajectory,  # noqa: E402
                                            TrajectoryLimits)
from arm_control.model.dynamics import ArmDynamics  # noqa: E402
from arm_control.model.kinematics import TwoLinkKinematics  # noqa: E402
from arm_control.model.plant import ArmPlant  # noqa: E402
from arm_control.model.world import ForbiddenSpace  # noqa: E402
from arm_control.planning.planner import Planner  # noqa: E402

HOLD_BEFORE_S = 0.5
TIMEOUT_S = 8.0
FINAL_AFTER_S = 1.0
PHYSICS_MS = 1                    # the plant's step and the recording's
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


class PlanHandOff:
    """The core's planner hand-off (``take_plan_requests`` → ``plan_and_time`` →
    ``on_timed_plan``). Each request is planned at once; the plan is ready after the CPU
    time that took (path + branch choice + timing) and is taken then, by an extra control
    cycle (``at_next_tick`` False), or only at the next regular tick (True)."""

    def __init__(self, core, planner, at_next_tick=False):
        self.core, self.planner, self.at_next_tick = core, planner, at_next_tick
        self.waiting = []             # (ready at, timed plan)
        self.plan_cpu_s, self.plan_wall_s = [], []
        self.delivered_s = math.nan

    def after_step(self, now_s):
        for request in self.core.take_plan_requests():
            cpu, wall = time.thread_time(), time.perf_counter()
            timed = self.core.plan_timer.plan_and_time(request, self.planner)
            cpu, wall = time.thread_time() - cpu, time.perf_counter() - wall
            self.plan_cpu_s.append(cpu)
            self.plan_wall_s.append(wall)
            ready = now_s + math.ceil(cpu * 1000.0 / PHYSICS_MS) * PHYSICS_MS / 1000.0
            self.waiting.append((ready, timed))

    def due(self, now_s, regular_tick):
        """Plans to take in a control cycle at ``now_s`` (None: no reason for a cycle)."""
        ready = [item for item in self.waiting if item[0] <= now_s + 1e-9]
        if not ready or (self.at_next_tick and not regular_tick):
            return None
        for item in ready:
            self.waiting.remove(item)
        return [timed for _, timed in ready]

    def deliver(self, now_s, plans):
        for timed in plans:
            self.core.on_timed_plan(now_s, timed)
            self.delivered_s = now_s


@dataclass
class Run:
    """What one controller did on one move, measured on the true state."""

    move_s: float = math.nan
    final_error_deg: float = math.nan
    overshoot_deg: float = math.nan      # n/a: never within tolerance
    peak_voltage: float = 0.0
    lowest_m: float = math.inf
    min_bus_v: float = math.nan
    peak_current_a: float = math.nan
    energy_j: float = math.nan           # drawn from the battery from the goal to arrival
    brownouts: int = 0
    reached: bool = False
    plan_arrived_s: float = math.nan     # ours: when the timed plan was taken
    trajectory_s: float = math.nan       # ours: how long its trajectory lasts
    plan_cpu_ms: float = math.nan        # ours: path + timing, CPU
    plan_wall_ms: float = math.nan       # ours: ... wall time (the machine is shared)
    cycle_cpu_ms: tuple = ()             # ours: CPU of each control cycle (planning apart)


def heights_m(arm, q):
    """min(y of the elbow, y of the tool): the lowest point of the links above the pivot."""
    q = np.atleast_2d(q)
    elbow_y = arm.shoulder.length_m * np.sin(q[:, 0])
    return np.minimum(elbow_y, elbow_y + arm.elbow.length_m * np.sin(q[:, 0] + q[:, 1]))


def measure(arm, controller_config, record, goal_q, start_q) -> Run:
    """Move time, final error, overshoot, peak voltage, lowest point and electrics of a
    recorded run."""
    tolerance = controller_config.goal_tolerance_rad
    still_below = controller_config.settled_velocity_rad_s
    times, states, voltages = (np.array(record[k]) for k in ('time', 'state', 'voltage'))
    power = np.array(record['power'])          # bus V, |motor current| A ×2, supply A
    after = times >= -1e-9
    t, x, v, p = times[after], states[after], voltages[after], power[after]
    error = np.abs(x[:, :2] - goal_q)
    inside = np.all(error < tolerance, axis=1)
    still = np.all(np.abs(x[:, 2:]) < still_below, axis=1)
    run = Run(peak_voltage=float(np.max(np.abs(v))), lowest_m=float(np.min(heights_m(arm, x))),
              brownouts=record['brownouts'])
    # Settled: inside from here to the end, and still at that moment.
    outside_after = np.flatnonzero(~inside)
    first_for_good = 0 if len(outside_after) == 0 else outside_after[-1] + 1
    candidates = np.flatnonzero(still[first_for_good:]) + first_for_good
    if len(candidates) and t[-1] - t[candidates[0]] >= FINAL_AFTER_S - 1e-9:
        i = candidates[0]
        run.move_s, run.reached = float(t[i]), True
        j = int(np.searchsorted(t, t[i] + FINAL_AFTER_S - 1e-9))
        run.final_error_deg = float(np.degrees(np.max(error[min(j, len(t) - 1)])))
    else:
        run.final_error_deg = float(np.degrees(np.max(error[-1])))
    moving = t <= (run.move_s if run.reached else t[-1]) + 1e-9
    run.min_bus_v = float(np.min(p[moving, 0]))
    run.peak_current_a = float(np.max(p[moving, 1:3]))
    run.energy_j = float(np.sum(p[moving, 0] * p[moving, 3]) * PHYSICS_MS / 1000.0)
    arrived = np.flatnonzero(inside)    # past the goal after both first get within tolerance
    if len(arrived):
        i = arrived[0]
        direction = np.where(np.abs(x[i, 2:]) > 1e-3, np.sign(x[i, 2:]),
                             np.sign(goal_q - x[i, :2]))
        past = direction * (x[i:, :2] - goal_q)
        run.overshoot_deg = float(np.degrees(max(np.max(past), 0.0)))
    return run


def simulate(arm, controller_config, controller, on_goal, start_q, seed, hand_off=None,
             plant_arm=None):
    """Hold at the start, give the goal at t = 0, run until settled for 1 s or timed out.

    Whole milliseconds: regular control cycles every period from −0.5 s, plus a cycle
    whenever ``hand_off`` has a plan ready; the true state is recorded every millisecond.
    The plant is ``plant_arm`` (default ``arm``: the controller's model is the truth).
    """
    plant = ArmPlant(plant_arm or arm, start_q, seed=seed)
    period_ms = 1000.0 / controller_config.loop_rate_hz
    if abs(period_ms - round(period_ms)) > 1e-9:
        raise ValueError(f'the bench needs a whole-millisecond period, not {period_ms} ms')
    period_ms = int(round(period_ms))
    first_ms, last_ms = -int(HOLD_BEFORE_S * 1000), int(TIMEOUT_S * 1000)
    record = {'time': [], 'state': [], 'voltage': [], 'power': []}
    still_count, needed = 0, int((FINAL_AFTER_S + 0.1) * 1000 / PHYSICS_MS)
    reference = None
    for now_ms in range(first_ms, last_ms, PHYSICS_MS):
        now_s = now_ms / 1000.0
        regular = (now_ms - first_ms) % period_ms == 0
        if now_ms == 0:
            on_goal(now_s)
        plans = hand_off.due(now_s, regular) if hand_off is not None else None
        if regular or plans is not None:
            if plans:
                hand_off.deliver(now_s, plans)
            plant.set_voltage(controller.step(now_s, plant.read()))
            if hand_off is not None:
                hand_off.after_step(now_s)
        plant.advance(PHYSICS_MS / 1000.0)
        state = np.array(plant.state)
        record['time'].append(now_s + PHYSICS_MS / 1000.0)
        record['state'].append(state)
        record['voltage'].append(np.array(plant.voltage))
        power = plant.power
        record['power'].append((power.bus_voltage, abs(power.motor_current_a[0]),
                                abs(power.motor_current_a[1]), power.supply_current_a))
        # Stop early once the arm has been still for a while (measure() decides the rest).
        if now_ms > 0 and np.all(np.abs(state[2:]) < controller_config.settled_velocity_rad_s):
            if reference is None or np.max(np.abs(state[:2] - reference)) > 1e-3:
                reference, still_count = state[:2].copy(), 0
            still_count += 1
            if still_count >= needed:
                break
        else:
            reference, still_count = None, 0
    record['brownouts'] = len(plant.brownouts) + (plant.browned_out_since_s is not None)
    return record


class _Timed:
    """A controller whose ``step`` CPU time is recorded."""

    def __init__(self, controller):
        self.controller, self.cpu_s = controller, []

    def step(self, now_s, reading):
        began = time.thread_time()
        voltage = self.controller.step(now_s, reading)
        self.cpu_s.append(time.thread_time() - began)
        return voltage


def run_ours(arm, controller_config, planner, start_q, goal_xy, seed, at_next_tick=False):
    core = ArmController(arm, controller_config)
    hand_off = PlanHandOff(core, planner, at_next_tick)
    timed = _Timed(core)
    record = simulate(arm, controller_config, timed, lambda t: core.submit_goal(t, *goal_xy),
                      start_q, seed, hand_off)
    goal_q = core.goals.goal_q if core.goals.goal_q is not None else np.full(2, np.nan)
    run = measure(arm, controller_config, record, goal_q, start_q)
    last = core.goals.plans.last
    if last is not None and last.ok:
        run.trajectory_s = last.trajectory.duration_s
        run.plan_arrived_s = hand_off.delivered_s
    run.plan_cpu_ms = 1000 * sum(hand_off.plan_cpu_s)
    run.plan_wall_ms = 1000 * sum(hand_off.plan_wall_s)
    run.cycle_cpu_ms = tuple(1000 * np.array(timed.cpu_s))
    return run


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


def fmt(value, spec='.2f'):
    return 'n/a' if value is None or not math.isfinite(value) else format(value, spec)


# --- the minimum time -------------------------------------------------------------------

def minimum_times(arm, controller_config, moves):
    """Per move: the direct-collocation minimum time under the electrical limits over the
    goal's free elbow branches (knots refined 25 → 50 → 100) and the 50 Hz minimum on the
    fastest branch."""
    dynamics, forbidden = ArmDynamics(arm), ForbiddenSpace(arm)
    planner = Planner(arm, config.load('planner')[1])
    validator = GoalValidator(arm)
    whole = TrajectoryLimits.from_config(arm, replace(
        controller_config, feedback_voltage_reserve=0.0, driving_voltage_reserve=0.0))
    out = {}
    for name, start_xy, goal_xy in moves:
        move = Move(name, start_xy, goal_xy, arm, controller_config, dynamics, forbidden, None)
        start_q = _start_configuration(move)
        best = None
        for goal_q in validator.free_configurations(*goal_xy):
            plan = planner.plan_to_configuration(start_q, goal_q)
            if not plan.ok:
                continue
            waypoints = np.array(plan.waypoints_rad)
            fast = time_optimal_trajectory(waypoints, dynamics, forbidden, whole)
            knots, guess = ocp.refined_minimum(arm, start_q, waypoints[-1],
                                               ocp.guess_from(fast, arm))
            if math.isfinite(knots[-1]) and (best is None or knots[-1] < best['min_s']):
                best = {'min_s': knots[-1], 'knots_s': knots, 'goal_q': list(waypoints[-1]),
                        'guess': guess}
        if best is None:
            out[name] = {'min_s': math.nan, 'knots_s': [], 'zoh_s': math.nan}
            continue
        best['zoh_s'] = ocp.minimum_time_zoh(arm, start_q, np.array(best['goal_q']),
                                             best.pop('guess'), best['min_s'], ZOH_PERIOD_S)
        out[name] = best
        print(f'  minimum {name}: {best["min_s"]:.3f} s (knots {ocp.KNOTS}: '
              f'{", ".join(f"{t:.4f}" for t in best["knots_s"])}), 50 Hz: '
              f'{best["zoh_s"]:.2f} s', file=sys.stderr, flush=True)
    return out


def load_or_compute_minimum(arm, controller_config, moves, cache_path):
    """The minimum times, from ``cache_path`` when it holds every move (a JSON file written
    by an earlier run of the same suite), else computed (and written there when given)."""
    if cache_path and Path(cache_path).exists():
        cached = json.loads(Path(cache_path).read_text())
        if all(name in cached for name, _, _ in moves):
            return cached
    out = minimum_times(arm, controller_config, moves)
    if cache_path:
        Path(cache_path).write_text(json.dumps(out, indent=1))
    return out


# --- the table --------------------------------------------------------------------------

def parse(argv):
    options = {'minimum': '--minimum' in argv, 'moves': None, 'set': {}, 'cache': None,
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
    minimum = (load_or_compute_minimum(arm, controller_config, moves, options['cache'])
               if options['minimum'] else {})

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
