"""Time-optimal trajectories against the true minimum time, on a suite of moves.

For each move of the default arm (start and goal points in arm_base): the planner's joint path
(``Planner.plan``; IK and a checked straight joint line when the planner is missing), then

- traj: ``time_optimal_trajectory`` from that path with the controller's limits (12 V
  driving, 12 V less the feedback reserve braking, the speed and acceleration limits): the
  path reshaped where that is faster, then timed; its duration, the time to compute it, its
  peak feedforward voltage, its lowest point;
- unshaped: the same on the planner's path as it is (``reshape=False``): what reshaping gains;
- 12 V: reshaped and timed with the whole 12 V both ways and no speed or acceleration
  limits, to separate what the margins cost from what the path and the method cost;
- minimum time: a direct-collocation optimal-control solve (casadi + IPOPT, Hermite-Simpson)
  of the free-path problem: the full coupled dynamics ẋ = f(x, u) written in casadi, |u| ≤
  12 V, the elbow and the tool above the floor (y ≥ 0), the joint limits and the elbow fold,
  start and end at rest. The knot count is refined (25, 50, 100) and each time printed, with
  the last change, which must be small (≤ 0.5 %) for the minimum time to count as settled.
  IPOPT finds a local optimum, started from the timed trajectory;
- preempted: halfway through, a new goal back at the start point, replanned and timed from
  the moving state (the arm's velocity then).

Times to compute are medians of 5 runs, as CPU time (what the computation costs) and wall
time (which also counts whatever else shares the machine's two cores).

Columns are plain functions of a ``Move`` returning {column name: text}; add one to
``COLUMNS`` (a closed-loop column goes next to the others).

    python bench/bench_trajectory.py            # all moves
    python bench/bench_trajectory.py 3          # only the first three
"""

from dataclasses import dataclass, field
import math
from pathlib import Path
import statistics
import sys
import time

import casadi
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))     # the package above

from arm_control import config  # noqa: E402
from arm_control.control.trajectory import (time_optimal_trajectory,  # noqa: E402
                                            trajectory_voltage, TrajectoryLimits)
from arm_control.model.dynamics import ArmDynamics, COULOMB_SMOOTHING_RAD_S  # noqa: E402
from arm_control.model.kinematics import TwoLinkKinematics, UnreachableError  # noqa: E402
from arm_control.model.world import ForbiddenSpace  # noqa: E402

KNOTS = (25, 50, 100)
CONVERGED = 0.005           # relative change of the minimum time that counts as settled
TIMING_REPEATS = 5

# (name, start point, goal point) in arm_base (m); the start takes the elbow-negative branch
# when it is free (the seed's start pose has the elbow at -90 deg).
SUITE = [
    ('stow -> back (over the top)', (0.25, 0.45), (-1.0, 1.0)),
    ('floor pickup -> low back', (1.2, 0.15), (-1.2, 0.3)),
    ('back -> floor pickup', (-1.0, 1.0), (1.2, 0.15)),
    ('floor -> full extension low', (1.2, 0.15), (1.75, 0.08)),
    ('short hop, mid', (1.1, 0.9), (1.2, 0.95)),
    ('short hop, floor', (1.2, 0.15), (1.3, 0.2)),
    ('stow -> tall reach', (0.25, 0.45), (0.2, 1.75)),
    ('floor pickup -> high score', (1.2, 0.15), (0.9, 1.5)),
    ('high back -> low front', (-1.2, 0.8), (1.5, 0.3)),
    ('mid -> stow', (1.1, 0.9), (0.25, 0.45)),
    ('low back -> low front', (-1.5, 0.15), (1.5, 0.15)),
    ('low front -> far low back', (1.6, 0.1), (-1.7, 0.1)),
]


@dataclass
class Move:
    """One move and what the columns share: the arm, its path, the trajectory."""

    name: str
    start_xy: tuple
    goal_xy: tuple
    arm: config.ArmConfig
    controller: config.ControllerConfig
    dynamics: ArmDynamics
    forbidden: ForbiddenSpace
    limits: TrajectoryLimits
    start_q: np.ndarray = None
    waypoints: np.ndarray = None
    path_source: str = ''
    path_ms: float = math.nan
    trajectory: object = None
    results: dict = field(default_factory=dict)


# --- the path -----------------------------------------------------------------------------

def timed(call, repeats=TIMING_REPEATS):
    """(result, median CPU ms, median wall ms): CPU time is what the computation costs;
    wall time also counts other processes sharing the machine's two cores."""
    cpu, wall, result = [], [], None
    for _ in range(repeats):
        wall_start, cpu_start = time.perf_counter(), time.process_time()
        result = call()
        cpu.append(time.process_time() - cpu_start)
        wall.append(time.perf_counter() - wall_start)
    return result, 1e3 * statistics.median(cpu), 1e3 * statistics.median(wall)


def _start_configuration(move: Move) -> np.ndarray:
    kinematics = TwoLinkKinematics(move.arm.shoulder.length_m, move.arm.elbow.length_m)
    positive, negative = kinematics.inverse(*move.start_xy)
    for q in (negative, positive):
        q = np.array([move.forbidden.to_joint_range(q[k], k) or q[k] for k in range(2)])
        if move.forbidden.is_free(q):
            return q
    raise ValueError(f'{move.name}: the start {move.start_xy} is forbidden on both branches')


def plan_path(move: Move) -> None:
    """The planner's waypoints (timed), or IK + a straight joint line checked free."""
    move.start_q = _start_configuration(move)
    move.waypoints, move.path_ms, _ = timed(
        lambda: _joint_path(move, move.start_q, move.goal_xy))


def _joint_path(move: Move, start_q, goal_xy) -> np.ndarray:
    if _PLANNER is not None:
        if move.arm not in _PLANNERS:
            _PLANNERS[move.arm] = _PLANNER(move.arm, config.load('planner')[1])
        plan = _PLANNERS[move.arm].plan(start_q, goal_xy)
        if not plan.ok:
            raise ValueError(f'{move.name}: no plan: {plan.reason}')
        move.path_source = 'planner'
        return np.array(plan.waypoints_rad)
    kinematics = TwoLinkKinematics(move.arm.shoulder.length_m, move.arm.elbow.length_m)
    step = config.load('planner')[1].check_step_rad
    candidates = []
    for q in kinematics.inverse(*goal_xy):
        q = np.array([move.forbidden.to_joint_range(q[k], k) or q[k] for k in range(2)])
        if move.forbidden.is_free(q) and move.forbidden.segment_is_free(start_q, q, step):
            candidates.append(q)
    if not candidates:
        raise UnreachableError(f'{move.name}: no straight joint line to the goal is free')
    move.path_source = 'IK line'
    return np.array([start_q, min(candidates, key=lambda q: float(np.abs(q - start_q).sum()))])


try:
    from arm_control.planning.planner import Planner as _PLANNER
except ImportError:             # not there yet: IK and a straight joint line instead
    _PLANNER = None
_PLANNERS = {}


# --- columns --------------------------------------------------------------------------

def column_path(move: Move) -> dict:
    return {'path': f'{move.path_source}, {len(move.waypoints)} pts',
            'path ms cpu': f'{move.path_ms:.1f}'}


def column_trajectory(move: Move) -> dict:
    """The trajectory the controller gets: duration, time to compute, peak volts, floor."""
    trajectory, cpu_ms, wall_ms = timed(lambda: time_optimal_trajectory(
        move.waypoints, move.dynamics, move.forbidden, move.limits))
    move.trajectory = trajectory
    times = np.linspace(0.0, trajectory.duration_s, 3000)
    peak = np.max(np.abs(trajectory_voltage(trajectory, move.dynamics, times)))
    q, _, _ = trajectory.sample_many(times)
    lowest_mm = 1e3 * float(np.min(_heights(move.arm, q)))
    move.results['traj_s'] = trajectory.duration_s
    return {'traj s': f'{trajectory.duration_s:.3f}',
            'timing ms cpu/wall': f'{cpu_ms:.1f}/{wall_ms:.0f}',
            'peak V': f'{peak:.2f}', 'lowest mm': f'{lowest_mm:.0f}'}


def column_unshaped(move: Move) -> dict:
    """The planner's path as it is, timed the same way."""
    trajectory = time_optimal_trajectory(move.waypoints, move.dynamics, move.forbidden,
                                         move.limits, reshape=False)
    move.results['unshaped_s'] = trajectory.duration_s
    return {'unshaped s': f'{trajectory.duration_s:.3f}'}


def column_full_voltage(move: Move) -> dict:
    """The same path and method at the whole 12 V with no speed or acceleration limits."""
    loose = TrajectoryLimits((1e3, 1e3), (1e4, 1e4), move.arm.battery.nominal_voltage)
    trajectory = time_optimal_trajectory(move.waypoints, move.dynamics, move.forbidden, loose)
    move.results['full_12v_s'] = trajectory.duration_s
    return {'12 V s': f'{trajectory.duration_s:.3f}'}


def column_minimum_time(move: Move) -> dict:
    """Direct collocation on 25, 50, 100 knots: the time must settle (last change ≤ 0.5 %)."""
    guess = _guess_from(move.trajectory, move.dynamics, move.arm.battery.nominal_voltage)
    times, solve_s = [], 0.0
    for knots in KNOTS:
        begin = time.perf_counter()
        result = minimum_time(move.arm, move.start_q, move.waypoints[-1], knots, guess)
        solve_s += time.perf_counter() - begin
        if result is None:
            times.append(math.nan)
            continue
        times.append(result['time_s'])
        guess = result
    best = times[-1]
    move.results['minimum_s'] = best
    out = {f'min N={n}': (f'{t:.4f}' if math.isfinite(t) else 'fail')
           for n, t in zip(KNOTS, times)}
    change = abs(times[-1] - times[-2]) / times[-1]
    out['last change'] = f'{100 * change:.2f} %' + ('' if change <= CONVERGED else ' (!)')
    out['solve s'] = f'{solve_s:.1f}'
    out['traj/min'] = f'{move.results["traj_s"] / best:.3f}'
    out['unshaped/min'] = f'{move.results["unshaped_s"] / best:.3f}'
    out['12 V/min'] = f'{move.results["full_12v_s"] / best:.3f}'
    return out


def column_preempted(move: Move) -> dict:
    """Halfway through, a new goal (back to the start point): replan from the moving state."""
    half = 0.5 * move.trajectory.duration_s
    q, qd, _ = move.trajectory.sample(half)
    waypoints = _joint_path(move, q, move.start_xy)
    trajectory, cpu_ms, wall_ms = timed(lambda: time_optimal_trajectory(
        waypoints, move.dynamics, move.forbidden, move.limits, start_velocity_rad_s=qd))
    times = np.linspace(0.0, trajectory.duration_s, 3000)
    peak = np.max(np.abs(trajectory_voltage(trajectory, move.dynamics, times)))
    return {'preempt |q̇| rad/s': f'{np.linalg.norm(qd):.2f}',
            'preempt s': f'{trajectory.duration_s:.3f}',
            'preempt ms cpu/wall': f'{cpu_ms:.1f}/{wall_ms:.0f}',
            'preempt peak V': f'{peak:.2f}'}


COLUMNS = [column_path, column_trajectory, column_unshaped, column_full_voltage,
           column_minimum_time,
           column_preempted]


def _heights(arm, q):
    """Lowest y of the elbow and the tool for each configuration (m)."""
    upper, fore = arm.shoulder.length_m, arm.elbow.length_m
    elbow_y = upper * np.sin(q[:, 0])
    return np.minimum(elbow_y, elbow_y + fore * np.sin(q[:, 0] + q[:, 1]))


# --- the minimum-time optimal control problem ----------------------------------------

def casadi_derivative(arm: config.ArmConfig):
    """f(x, u) of ``ArmDynamics.derivative`` in casadi: x = [θa, θb, ωa, ωb], u = [Va, Vb].

    M θ̈ + C θ̇ + τg = τ_motor(V, θ̇) − τ_friction(θ̇) (Pedersen), the motors as GearMotor.
    """
    dynamics = ArmDynamics(arm)
    upper, fore = arm.shoulder, arm.elbow
    ma, mb = upper.mass_kg, fore.mass_kg
    ra, rb, la = upper.com_from_joint_m, fore.com_from_joint_m, upper.length_m
    g = arm.gravity_mps2
    x, u = casadi.SX.sym('x', 4), casadi.SX.sym('u', 2)
    qa, qb, wa, wb = x[0], x[1], x[2], x[3]
    coupling = mb * la * rb * casadi.cos(qb)
    m00 = (ma * ra ** 2 + mb * (la ** 2 + rb ** 2) + upper.inertia_about_com_kgm2
           + fore.inertia_about_com_kgm2 + 2 * coupling)
    m01 = mb * rb ** 2 + fore.inertia_about_com_kgm2 + coupling
    m11 = mb * rb ** 2 + fore.inertia_about_com_kgm2
    h = mb * la * rb * casadi.sin(qb)
    coriolis = [-h * wb * wa - h * (wa + wb) * wb, h * wa * wa]
    outer = g * mb * rb * casadi.cos(qa + qb)
    gravity = [g * (ma * ra + mb * la) * casadi.cos(qa) + outer, outer]
    net = []
    for k, (joint, motor, w) in enumerate(zip(arm.joints, dynamics.motors, (wa, wb))):
        motor_torque = (motor.gear_ratio * motor.kt_nm_per_a * motor.count
                        * (u[k] - motor.gear_ratio * w / motor.kv_rad_per_s_per_v)
                        / motor.resistance_ohm)
        friction = (joint.viscous_friction_nm_s_per_rad * w
                    + joint.coulomb_friction_nm * casadi.tanh(w / COULOMB_SMOOTHING_RAD_S))
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


def _guess_from(trajectory, dynamics, max_voltage):
    """An initial guess: the trajectory's states and clipped feedforward on 101 times."""
    times = np.linspace(0.0, trajectory.duration_s, 101)
    q, qd, _ = trajectory.sample_many(times)
    volts = np.clip(trajectory_voltage(trajectory, dynamics, times), -max_voltage, max_voltage)
    return {'time_s': trajectory.duration_s, 'fraction': times / trajectory.duration_s,
            'state': np.hstack([q, qd]), 'voltage': volts}


def _resample(guess, fractions):
    state = np.column_stack([np.interp(fractions, guess['fraction'], guess['state'][:, k])
                             for k in range(4)])
    volts = np.column_stack([np.interp(fractions, guess['fraction'], guess['voltage'][:, k])
                             for k in range(2)])
    return state, volts


def minimum_time(arm, start_q, goal_q, knots, guess):
    """min T s.t. Hermite-Simpson collocation of f on ``knots`` intervals, |u| ≤ V_max,
    floor, joint limits and elbow fold at knots and midpoints, rest at both ends."""
    f = casadi_derivative(arm)
    opti = casadi.Opti()
    x = opti.variable(4, knots + 1)
    u = opti.variable(2, knots + 1)
    xm = opti.variable(4, knots)
    um = opti.variable(2, knots)
    duration = opti.variable()
    h = duration / knots
    fk = [f(x[:, k], u[:, k]) for k in range(knots + 1)]
    for k in range(knots):
        fm = f(xm[:, k], um[:, k])
        opti.subject_to(xm[:, k] == 0.5 * (x[:, k] + x[:, k + 1]) + h / 8 * (fk[k] - fk[k + 1]))
        opti.subject_to(x[:, k + 1] - x[:, k] == h / 6 * (fk[k] + 4 * fm + fk[k + 1]))
    limit_v = arm.battery.nominal_voltage
    fold = math.pi - arm.world.min_elbow_fold_rad
    upper, fore = arm.shoulder.length_m, arm.elbow.length_m
    for states, volts in ((x, u), (xm, um)):
        opti.subject_to(opti.bounded(-limit_v, casadi.vec(volts), limit_v))
        opti.subject_to(opti.bounded(arm.shoulder.min_angle_rad, states[0, :],
                                     arm.shoulder.max_angle_rad))
        opti.subject_to(opti.bounded(max(arm.elbow.min_angle_rad, -fold), states[1, :],
                                     min(arm.elbow.max_angle_rad, fold)))
        elbow_y = upper * casadi.sin(states[0, :])
        opti.subject_to(elbow_y >= 0)
        opti.subject_to(elbow_y + fore * casadi.sin(states[0, :] + states[1, :]) >= 0)
    opti.subject_to(x[:, 0] == np.concatenate([start_q, [0.0, 0.0]]))
    opti.subject_to(x[:, knots] == np.concatenate([goal_q, [0.0, 0.0]]))
    opti.subject_to(opti.bounded(0.05, duration, 20.0))
    opti.minimize(duration)

    fractions = np.linspace(0.0, 1.0, knots + 1)
    mids = 0.5 * (fractions[1:] + fractions[:-1])
    state, volts = _resample(guess, fractions)
    state_m, volts_m = _resample(guess, mids)
    opti.set_initial(x, state.T)
    opti.set_initial(u, volts.T)
    opti.set_initial(xm, state_m.T)
    opti.set_initial(um, volts_m.T)
    opti.set_initial(duration, guess['time_s'])
    opti.solver('ipopt', {'print_time': False},
                {'print_level': 0, 'max_iter': 3000, 'tol': 1e-8, 'sb': 'yes'})
    try:
        solution = opti.solve()
    except RuntimeError:
        return None
    x_value = np.array(solution.value(x)).T
    u_value = np.array(solution.value(u)).T
    return {'time_s': float(solution.value(duration)), 'fraction': fractions,
            'state': x_value, 'voltage': u_value}


# --- the table ------------------------------------------------------------------------

def main(count=None):
    arm, controller = config.load('controller')
    dynamics, forbidden = ArmDynamics(arm), ForbiddenSpace(arm)
    limits = TrajectoryLimits.from_config(arm, controller)
    rows = []
    for name, start_xy, goal_xy in SUITE[:count]:
        move = Move(name, start_xy, goal_xy, arm, controller, dynamics, forbidden, limits)
        plan_path(move)
        row = {'move': name}
        for column in COLUMNS:
            row.update(column(move))
        rows.append(row)
        print(' | '.join(f'{k}={v}' for k, v in row.items()), file=sys.stderr, flush=True)
    keys = list(dict.fromkeys(k for row in rows for k in row))
    print(f'trajectory limits: {limits.budget[0]:g} V driving, {limits.budget[1]:g} V '
          f'braking, velocity {limits.max_velocity_rad_s} rad/s, acceleration '
          f'{limits.max_acceleration_rad_s2} rad/s^2; minimum time at '
          f'{arm.battery.nominal_voltage:g} V, '
          'free path')
    print('| ' + ' | '.join(keys) + ' |')
    print('|' + '---|' * len(keys))
    for row in rows:
        print('| ' + ' | '.join(str(row.get(k, '')) for k in keys) + ' |')
    ratios = [float(r['traj/min']) for r in rows]
    print(f'traj/min: worst {max(ratios):.3f}, median {statistics.median(ratios):.3f}')


if __name__ == '__main__':
    main(int(sys.argv[1]) if len(sys.argv) > 1 else None)
