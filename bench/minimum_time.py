"""The minimum-time reference of the benchmarks: optimal control under the sim's own limits.

Direct collocation (casadi + IPOPT, Hermite-Simpson) of the free-path problem: the full
coupled dynamics ẋ = f(x, u) of ``ArmDynamics`` written in casadi (checked against it),
u the volts the motor controllers apply, the elbow and the tool above the floor (y ≥ 0), the
joint limits and the elbow fold, start and end at rest. Under the electrical limits of
DESIGN.md §4b, as ``ArmPlant`` applies them, at every knot and midpoint:

    |V_j − e_j·ω_j| ≤ I_limit·R_j            (each motor's stator current within its limit)
    |V_j| ≤ V_bus,  V_bus ≥ V_brownout,
    V_bus² − V_nominal·V_bus + R_battery·Σ_j n_j·V_j·I_j = 0,   I_j = (V_j − e_j·ω_j)/R_j,

V_bus a decision variable per point (the equation's upper root: V_bus ≥ V_brownout >
V_nominal/2). ``electrical=False`` is the ideal supply: |V| ≤ V_nominal and nothing else.
IPOPT finds a local optimum, started from a timed trajectory (``guess_from``).
"""

from dataclasses import replace
import hashlib
import json
import math
from pathlib import Path
import sys

import casadi
import numpy as np

from arm_control import config
from arm_control.model.dynamics import ArmDynamics, COULOMB_SMOOTHING_RAD_S
from arm_control.model.electrical import PowerSupply
from arm_control.model.world import ForbiddenSpace
from arm_control.planning.planner import Planner
from arm_control.plans.goals import GoalValidator
from arm_control.timing import time_optimal_trajectory, TrajectoryLimits

KNOTS = (25, 50, 100)
CACHE = Path(__file__).resolve().parent / '.minimum_cache.json'   # suite_minimums' answers
CONVERGED = 0.005           # relative change of the minimum time that counts as settled


def casadi_derivative(arm):
    """f(x, u) of ``ArmDynamics.derivative`` in casadi: x = [θa, θb, ωa, ωb], u = [Va, Vb].

    M θ̈ + C θ̇ + τg = τ_motor(V, θ̇) − τ_friction(θ̇) (Pedersen), the motors as GearMotor.
    """
    dynamics = ArmDynamics(arm)
    x, u = casadi.SX.sym('x', 4), casadi.SX.sym('u', 2)
    qb, wa, wb = x[1], x[2], x[3]
    coupling = dynamics.beta * casadi.cos(qb)
    m00, m01, m11 = dynamics.alpha + 2 * coupling, dynamics.gamma + coupling, dynamics.gamma
    h = dynamics.beta * casadi.sin(qb)
    coriolis = [-h * wb * wa - h * (wa + wb) * wb, h * wa * wa]
    fore = dynamics.g_fore * casadi.cos(x[0] + qb)
    gravity = [dynamics.g_upper * casadi.cos(x[0]) + fore, fore]
    net = []
    for k, w in enumerate((wa, wb)):
        motor_torque = (u[k] - dynamics.emf_v_per_rad_s[k] * w) / dynamics.volts_per_nm[k]
        friction = (dynamics.viscous[k] * w
                    + dynamics.coulomb[k] * casadi.tanh(w / COULOMB_SMOOTHING_RAD_S))
        net.append(motor_torque - friction - coriolis[k] - gravity[k])
    det = m00 * m11 - m01 * m01
    acc_a = (m11 * net[0] - m01 * net[1]) / det
    acc_b = (m00 * net[1] - m01 * net[0]) / det
    f = casadi.Function('f', [x, u], [casadi.vertcat(wa, wb, acc_a, acc_b)])
    rng = np.random.default_rng(0)          # the two models must agree
    for _ in range(20):
        xs, us = rng.uniform(-3, 3, 4), rng.uniform(-12, 12, 2)
        mismatch = np.max(np.abs(np.array(f(xs, us)).ravel()
                                 - np.array(dynamics.derivative(list(xs), list(us)))))
        assert mismatch < 1e-9, f'casadi model differs from ArmDynamics by {mismatch}'
    return f


def guess_from(trajectory, arm):
    """An initial guess: the trajectory's states, its feedforward volts as the motor
    controllers would apply them, and the bus they leave, on 101 times."""
    dynamics = ArmDynamics(arm)
    supply = PowerSupply(arm, dynamics.motors)
    times = np.linspace(0.0, trajectory.duration_s, 101)
    q, qd, qdd = trajectory.sample_many(times)
    volts = dynamics.voltages(q, qd, qdd)
    powers = [supply.solve(v, w) for v, w in zip(volts, qd)]
    return {'time_s': trajectory.duration_s, 'fraction': times / trajectory.duration_s,
            'state': np.hstack([q, qd]),
            'voltage': np.array([p.applied_v for p in powers]),
            'bus': np.array([p.bus_voltage for p in powers])}


def _resample(guess, fractions):
    def column(key, k=None):
        values = guess[key] if k is None else guess[key][:, k]
        return np.interp(fractions, guess['fraction'], values)
    state = np.column_stack([column('state', k) for k in range(4)])
    volts = np.column_stack([column('voltage', k) for k in range(2)])
    return state, volts, column('bus')


class _Electrical:
    """The supply's constraints on (state, volts, bus) columns of an ``Opti`` problem."""

    def __init__(self, arm):
        dynamics = ArmDynamics(arm)
        battery = arm.battery
        self.nominal, self.resistance = battery.nominal_voltage, battery.resistance_ohm
        self.brownout = battery.brownout_voltage
        self.motors = dynamics.motors
        self.windows = [joint.current_limit_a * motor.resistance_ohm
                        for joint, motor in zip(arm.joints, dynamics.motors)]

    def impose(self, opti, states, volts, bus):
        power = 0
        for j, motor in enumerate(self.motors):
            drive = volts[j, :] - motor.back_emf_v_per_rad_s * states[2 + j, :]
            if math.isfinite(self.windows[j]):
                opti.subject_to(opti.bounded(-self.windows[j], drive, self.windows[j]))
            opti.subject_to(volts[j, :] <= bus)
            opti.subject_to(-bus <= volts[j, :])
            power = power + motor.count * volts[j, :] * drive / motor.resistance_ohm
        opti.subject_to(bus * bus - self.nominal * bus + self.resistance * power == 0)
        opti.subject_to(bus >= self.brownout)


def _floor_and_limits(opti, arm, states):
    fold = math.pi - arm.world.min_elbow_fold_rad
    upper, fore = arm.shoulder.length_m, arm.elbow.length_m
    opti.subject_to(opti.bounded(arm.shoulder.min_angle_rad, states[0, :],
                                 arm.shoulder.max_angle_rad))
    opti.subject_to(opti.bounded(max(arm.elbow.min_angle_rad, -fold), states[1, :],
                                 min(arm.elbow.max_angle_rad, fold)))
    elbow_y = upper * casadi.sin(states[0, :])
    opti.subject_to(elbow_y >= 0)
    opti.subject_to(elbow_y + fore * casadi.sin(states[0, :] + states[1, :]) >= 0)


def minimum_time(arm, start_q, goal_q, knots, guess, electrical=True):
    """min T s.t. Hermite-Simpson collocation of f on ``knots`` intervals, the supply's
    limits (or |u| ≤ V_nominal), floor, joint limits and elbow fold at knots and
    midpoints, rest at both ends. None when IPOPT fails."""
    f = casadi_derivative(arm)
    opti = casadi.Opti()
    x, u = opti.variable(4, knots + 1), opti.variable(2, knots + 1)
    xm, um = opti.variable(4, knots), opti.variable(2, knots)
    duration = opti.variable()
    h = duration / knots
    fk = [f(x[:, k], u[:, k]) for k in range(knots + 1)]
    for k in range(knots):
        fm = f(xm[:, k], um[:, k])
        opti.subject_to(xm[:, k] == 0.5 * (x[:, k] + x[:, k + 1]) + h / 8 * (fk[k] - fk[k + 1]))
        opti.subject_to(x[:, k + 1] - x[:, k] == h / 6 * (fk[k] + 4 * fm + fk[k + 1]))
    fractions = np.linspace(0.0, 1.0, knots + 1)
    mids = 0.5 * (fractions[1:] + fractions[:-1])
    supply = _Electrical(arm)
    buses = []
    for states, volts, where in ((x, u, fractions), (xm, um, mids)):
        _floor_and_limits(opti, arm, states)
        state, voltage, bus_guess = _resample(guess, where)
        opti.set_initial(states, state.T)
        opti.set_initial(volts, voltage.T)
        if electrical:
            bus = opti.variable(1, len(where))
            supply.impose(opti, states, volts, bus)
            opti.set_initial(bus, bus_guess[None])
            buses.append(bus)
        else:
            limit = arm.battery.nominal_voltage
            opti.subject_to(opti.bounded(-limit, casadi.vec(volts), limit))
    opti.subject_to(x[:, 0] == np.concatenate([start_q, [0.0, 0.0]]))
    opti.subject_to(x[:, knots] == np.concatenate([goal_q, [0.0, 0.0]]))
    opti.subject_to(opti.bounded(0.05, duration, 20.0))
    opti.minimize(duration)
    opti.set_initial(duration, guess['time_s'])
    opti.solver('ipopt', {'print_time': False},
                {'print_level': 0, 'max_iter': 3000, 'tol': 1e-8, 'sb': 'yes'})
    try:
        solution = opti.solve()
    except RuntimeError:
        return None
    bus = (np.array(solution.value(buses[0])).ravel() if electrical
           else np.full(knots + 1, arm.battery.nominal_voltage))
    return {'time_s': float(solution.value(duration)), 'fraction': fractions,
            'state': np.array(solution.value(x)).T, 'voltage': np.array(solution.value(u)).T,
            'bus': bus}


def refined_minimum(arm, start_q, goal_q, guess, electrical=True, knots=KNOTS):
    """The minimum time on each knot count in turn, each solve started from the last:
    (times, the last solution or the guess)."""
    times = []
    for count in knots:
        result = minimum_time(arm, start_q, goal_q, count, guess, electrical)
        times.append(math.nan if result is None else result['time_s'])
        guess = result or guess
    return times, guess


def minimum_time_zoh(arm, start_q, goal_q, guess, minimum_s, period_s=0.02, substeps=10):
    """The fewest whole periods of constant voltage that take the arm from rest to rest at
    the goal (RK4 on ``substeps`` per period, the floor at every period's end): the least
    time a controller holding each command for a period can take. The voltage held is
    applied as it is: within the current limits and the bus at every substep (the motor
    controllers never have to lower it)."""
    f = casadi_derivative(arm)
    upper, fore = arm.shoulder.length_m, arm.elbow.length_m
    supply = _Electrical(arm)
    first = max(1, math.ceil(minimum_s / period_s - 1e-9))
    for count in range(first, first + 6):
        opti = casadi.Opti()
        x = opti.variable(4, count + 1)
        u = opti.variable(2, count)
        bus = opti.variable(1, count * substeps)
        h = period_s / substeps
        inner, held = [], []
        for k in range(count):
            state = x[:, k]
            for _ in range(substeps):
                inner.append(state)
                held.append(u[:, k])
                k1 = f(state, u[:, k])
                k2 = f(state + h / 2 * k1, u[:, k])
                k3 = f(state + h / 2 * k2, u[:, k])
                k4 = f(state + h * k3, u[:, k])
                state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            opti.subject_to(x[:, k + 1] == state)
        supply.impose(opti, casadi.horzcat(*inner), casadi.horzcat(*held), bus)
        elbow_y = upper * casadi.sin(x[0, :])
        opti.subject_to(elbow_y >= 0)
        opti.subject_to(elbow_y + fore * casadi.sin(x[0, :] + x[1, :]) >= 0)
        opti.subject_to(x[:, 0] == np.concatenate([start_q, [0.0, 0.0]]))
        opti.subject_to(x[:, count] == np.concatenate([goal_q, [0.0, 0.0]]))
        opti.minimize(1e-4 * casadi.sumsqr(u))
        fractions = np.linspace(0.0, 1.0, count + 1)
        state, _, _ = _resample(guess, fractions)
        _, volts, _ = _resample(guess, 0.5 * (fractions[1:] + fractions[:-1]))
        _, _, bus_guess = _resample(guess, np.linspace(0.0, 1.0, count * substeps))
        opti.set_initial(x, state.T)
        opti.set_initial(u, volts.T)
        opti.set_initial(bus, bus_guess[None])
        opti.solver('ipopt', {'print_time': False},
                    {'print_level': 0, 'max_iter': 500, 'sb': 'yes'})
        try:
            opti.solve()
            return count * period_s
        except RuntimeError:
            continue
    return math.nan


# --- the minimum of a suite of moves, cached ------------------------------------------------

def suite_minimums(arm, controller_config, moves, cache_path=None, zoh_period_s=0.02):
    """Per move (name, start_q, goal_xy): the minimum under the electrical limits, the least
    over the goal's free elbow branches (``refined_minimum``, started from a timing with no
    reserves), and the 50 Hz minimum on that branch: {'min_s', 'knots_s', 'goal_q', 'zoh_s'}.
    Kept in ``cache_path`` (JSON) under the move, its start and this arm's parameters, so a
    changed arm or start is solved again (minutes for a suite)."""
    path = Path(cache_path) if cache_path else None
    cache = json.loads(path.read_text()) if path and path.exists() else {}
    digest = hashlib.sha1(repr(arm).encode()).hexdigest()[:12]
    dynamics, forbidden = ArmDynamics(arm), ForbiddenSpace(arm)
    planner = Planner(arm, config.load('planner')[1])
    validator = GoalValidator(arm)
    whole = TrajectoryLimits.from_config(arm, replace(
        controller_config, feedback_voltage_reserve=0.0, driving_voltage_reserve=0.0))
    out = {}
    for name, start_q, goal_xy in moves:
        start_q = np.asarray(start_q, float)
        key = f'{name} | {np.round(start_q, 4).tolist()} -> {list(goal_xy)} | arm {digest}'
        if key in cache:
            out[name] = cache[key]
            continue
        best = None
        for goal_q in validator.free_configurations(*goal_xy):
            plan = planner.plan_to_configuration(start_q, goal_q)
            if not plan.ok:
                continue
            waypoints = np.array(plan.waypoints_rad)
            fast = time_optimal_trajectory(waypoints, dynamics, forbidden, whole)
            knots, guess = refined_minimum(arm, start_q, waypoints[-1], guess_from(fast, arm))
            if math.isfinite(knots[-1]) and (best is None or knots[-1] < best['min_s']):
                best = {'min_s': knots[-1], 'knots_s': knots, 'goal_q': list(waypoints[-1]),
                        'guess': guess}
        if best is None:
            best = {'min_s': math.nan, 'knots_s': [], 'goal_q': [], 'zoh_s': math.nan}
        else:
            best['zoh_s'] = minimum_time_zoh(arm, start_q, np.array(best['goal_q']),
                                             best.pop('guess'), best['min_s'], zoh_period_s)
        out[name] = cache[key] = best
        print(f'  minimum {name}: {best["min_s"]:.3f} s (knots {KNOTS}: '
              f'{", ".join(f"{t:.4f}" for t in best["knots_s"])}), 50 Hz: '
              f'{best["zoh_s"]:.2f} s', file=sys.stderr, flush=True)
        if path:
            path.write_text(json.dumps(cache, indent=1))
    return out
