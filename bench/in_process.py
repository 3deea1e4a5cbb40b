"""The controller and the plant in one process, in simulated time: one move, timed.

The closed loop the nodes run over ROS, with no ROS: ``ArmController`` steps at its rate on
``ArmPlant`` (sensor noise, the electrical limits, physics on 1 ms steps), the goal given at
t = 0 after 0.5 s held at the start. Planning runs in this process the moment the goal
arrives, and its plan is taken after the CPU time it cost (``PlanHandOff``): the arm waits
exactly the planning time. The true state is recorded every millisecond (``simulate``) and
``measure`` gives the move time, errors and electrics. Used by ``bench_controller``,
``bench_ros`` and ``bench_sysid``.
"""

from dataclasses import dataclass
import math
import time

import numpy as np

from arm_control.control.controller import ArmController
from arm_control.model.plant import ArmPlant
from arm_control.plans.port import HeldRequests, InProcessPlanning

HOLD_BEFORE_S = 0.5
TIMEOUT_S = 8.0
FINAL_AFTER_S = 1.0
PHYSICS_MS = 1                    # the plant's step and the recording's


class PlanHandOff:
    """The core's requests, held as it hands them on (its ``Planning``: ``HeldRequests``),
    sent after its step to ``InProcessPlanning``, whose answers go to ``on_timed_plan``
    after the CPU time they took (path + branch choice + timing): by an extra control cycle
    (``at_next_tick`` False), or only at the next regular tick (True)."""

    def __init__(self, core, planner, at_next_tick=False):
        self.core, self.at_next_tick = core, at_next_tick
        self.answers = []             # from the planning, not yet ready
        self.planning = InProcessPlanning(core, planner, self.answers.append)
        self.held = core.planning = HeldRequests()
        self.waiting = []             # (ready at, timed plan)
        self.plan_cpu_s, self.plan_wall_s = [], []
        self.delivered_s = math.nan

    def after_step(self, now_s):
        for request in self.held.take():
            cpu, wall = time.thread_time(), time.perf_counter()
            self.planning.send([request])
            cpu, wall = time.thread_time() - cpu, time.perf_counter() - wall
            timed = self.answers.pop()
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


class TimedCore:
    """An ``ArmController`` as ``simulate`` drives a controller (``step`` gives [Va, Vb]),
    the CPU time of each step recorded."""

    def __init__(self, controller):
        self.controller, self.cpu_s = controller, []

    def step(self, now_s, reading):
        began = time.thread_time()
        voltage = self.controller.step(now_s, reading).volts
        self.cpu_s.append(time.thread_time() - began)
        return voltage


def run_ours(arm, controller_config, planner, start_q, goal_xy, seed, at_next_tick=False):
    core = ArmController(arm, controller_config)
    hand_off = PlanHandOff(core, planner, at_next_tick)
    timed = TimedCore(core)
    record = simulate(arm, controller_config, timed, lambda t: core.submit_goal(t, *goal_xy),
                      start_q, seed, hand_off)
    final = core.last_step
    goal_q = final.goal_q if final and final.goal_q is not None else np.full(2, np.nan)
    run = measure(arm, controller_config, record, goal_q, start_q)
    last = core.goals.plans.last
    if last is not None and last.ok:
        run.trajectory_s = last.trajectory.duration_s
        run.plan_arrived_s = hand_off.delivered_s
    run.plan_cpu_ms = 1000 * sum(hand_off.plan_cpu_s)
    run.plan_wall_ms = 1000 * sum(hand_off.plan_wall_s)
    run.cycle_cpu_ms = tuple(1000 * np.array(timed.cpu_s))
    return run


def fmt(value, spec='.2f'):
    return 'n/a' if value is None or not math.isfinite(value) else format(value, spec)
