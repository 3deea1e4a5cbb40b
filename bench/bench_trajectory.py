"""Time-optimal trajectories against the true minimum time, on a suite of moves.

For each move of the default arm (start and goal points in arm_base): the planner's joint path
(``Planner.plan``; IK and a checked straight joint line when the planner is missing), then

- traj: ``time_optimal_trajectory`` from that path with the controller's limits (the bus
  less no reserve driving, less the feedback reserve braking; the current limits; speed and
  acceleration caps when set): the path reshaped where that is faster, then timed; its
  duration, the time to compute it, and along it, with the sim's electrical model
  (``PowerSupply.solve`` on its feedforward volts): the peak commanded |V|, the lowest bus
  voltage, the peak motor current, and the share of samples the motor controllers would
  have to lower (clipped); its lowest point;
- unshaped: the same on the planner's path as it is (``reshape=False``): what reshaping gains;
- half reserve, no reserve: reshaped and timed with half the reserves, and with the whole
  supply both ways: what the reserves cost;
- ideal supply: the controller's limits on an ideal supply (no current limit, no battery
  resistance): what the electrical limits cost, and the figure to compare with the timing
  of a 12 V-only planner;
- minimum time (``minimum_time``): direct collocation (casadi + IPOPT) of the free-path
  problem under the same electrical limits the sim imposes (current limits, bus sag,
  brownout), floor, joint limits and elbow fold, rest at both ends. The knot count is
  refined (25, 50, 100) and each time printed, with the last change, which must be small
  (≤ 0.5 %) for the minimum time to count as settled. IPOPT finds a local optimum, started
  from the timed trajectory;
- preempted: halfway through, a new goal back at the start point, replanned and timed from
  the moving state (the arm's velocity then).

Times to compute are medians of 5 runs, as CPU time (what the computation costs) and wall
time (which also counts whatever else shares the machine's two cores).

``--what-if``: the current limits at 40, 60, 80 and 120 A per motor (and none): per move,
the timed trajectory's duration against the electrical minimum at that limit.

``--planning``: what a goal costs before the arm moves, as the nodes run it (``planning_time``):
the planner node's work (paths, branch choice) and the worker's quick timing, per move of this
suite and of the FRC robot's preset moves, and the refinement that takes over while the arm
moves. Loaded, with two busy loops beside it: ``python bench/planning_time.py --loaded``.

Columns are plain functions of a ``Move`` returning {column name: text}; add one to
``COLUMNS`` (a closed-loop column goes next to the others).

    python bench/bench_trajectory.py            # all moves
    python bench/bench_trajectory.py 3          # only the first three
    python bench/bench_trajectory.py --what-if
    python bench/bench_trajectory.py --planning [repeats]
"""

import dataclasses
from dataclasses import dataclass, field
import math
from pathlib import Path
import statistics
import sys
import time

BENCH = Path(__file__).resolve().parent
sys.path[:0] = [str(BENCH), str(BENCH.parent)]       # the OCP beside, the package above

import minimum_time as ocp  # noqa: E402
import numpy as np  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.model.dynamics import ArmDynamics  # noqa: E402
from arm_control.model.electrical import PowerSupply  # noqa: E402
from arm_control.model.kinematics import TwoLinkKinematics, UnreachableError  # noqa: E402
from arm_control.model.world import ForbiddenSpace  # noqa: E402
from arm_control.timing import (time_optimal_trajectory,  # noqa: E402
                                TrajectoryError, TrajectoryLimits)

TIMING_REPEATS = 5
WHAT_IF_LIMITS_A = (40.0, 60.0, 80.0, 120.0, math.inf)

# (name, start point, goal point) in arm_base (m); the start takes the elbow-negative branch
# when it is free (the seed's start pose has the elbow at -90 deg).
SUITE = [
    ('stow -> back (over the top)', (0.25, 0.45), (-1.0, 1.0)),
    ('floor pickup -> low back', (1.2, 0.15), (-1.2, 0.3)),
    ('back -> floor pickup', (-1.0, 1.0), (1.2, 0.15)),
    ('floor -> full extension low', (1.2, 0.15), (1.75, 0.1)),
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

def electrical(arm, trajectory, count=1500):
    """Along the trajectory, with the sim's electrical model on its feedforward volts:
    peak commanded |V|, lowest bus voltage, the peak motor current the feedforward asks for
    (A, before any limiting), the share of samples the motor controllers would lower (the
    current limit or the bus), and whether any sample browns out."""
    dynamics = ArmDynamics(arm)
    supply = PowerSupply(arm, dynamics.motors)
    times = np.linspace(0.0, trajectory.duration_s, count)
    q, qd, qdd = trajectory.sample_many(times)
    volts = dynamics.voltages(q, qd, qdd)
    powers = [supply.solve(v, w) for v, w in zip(volts, qd)]
    applied = np.array([p.applied_v for p in powers])
    asked = [[m.current_a(v[j], w[j]) for j, m in enumerate(dynamics.motors)]
             for v, w in zip(volts, qd)]
    return {'peak_v': float(np.max(np.abs(volts))),
            'min_bus_v': min(p.bus_voltage for p in powers),
            'peak_a': float(np.max(np.abs(asked))),
            'clipped': float(np.mean(np.any(np.abs(applied - volts) > 0.05, axis=1))),
            'brownout': any(p.browned_out for p in powers)}


def _electrical_cells(arm, trajectory, prefix=''):
    e = electrical(arm, trajectory)
    return {f'{prefix}peak V': f'{e["peak_v"]:.2f}',
            f'{prefix}min bus V': f'{e["min_bus_v"]:.2f}' + (' BROWNOUT' if e['brownout']
                                                             else ''),
            f'{prefix}peak A': f'{e["peak_a"]:.0f}',
            f'{prefix}clipped': f'{100 * e["clipped"]:.0f} %'}


def column_path(move: Move) -> dict:
    return {'path': f'{move.path_source}, {len(move.waypoints)} pts',
            'path ms cpu': f'{move.path_ms:.1f}'}


def column_trajectory(move: Move) -> dict:
    """The trajectory the controller gets: duration, time to compute, electrics, floor."""
    trajectory, cpu_ms, wall_ms = timed(lambda: time_optimal_trajectory(
        move.waypoints, move.dynamics, move.forbidden, move.limits))
    move.trajectory = trajectory
    q, _, _ = trajectory.sample_many(np.linspace(0.0, trajectory.duration_s, 3000))
    move.results['traj_s'] = trajectory.duration_s
    return {'traj s': f'{trajectory.duration_s:.3f}',
            'timing ms cpu/wall': f'{cpu_ms:.1f}/{wall_ms:.0f}',
            **_electrical_cells(move.arm, trajectory),
            'lowest mm': f'{1e3 * float(np.min(_heights(move.arm, q))):.0f}'}


def column_unshaped(move: Move) -> dict:
    """The planner's path as it is, timed the same way."""
    trajectory = time_optimal_trajectory(move.waypoints, move.dynamics, move.forbidden,
                                         move.limits, reshape=False)
    move.results['unshaped_s'] = trajectory.duration_s
    return {'unshaped s': f'{trajectory.duration_s:.3f}'}


def column_reserves(move: Move) -> dict:
    """The same path and method with half the reserves, and with the whole supply both ways:
    what the reserves cost."""
    out = {}
    for key, label, share in (('half_reserve_s', 'half reserve', 0.5),
                              ('no_reserve_s', 'no reserve', 0.0)):
        limits = TrajectoryLimits.from_config(move.arm, dataclasses.replace(
            move.controller,
            driving_voltage_reserve=share * move.controller.driving_voltage_reserve,
            feedback_voltage_reserve=share * move.controller.feedback_voltage_reserve))
        trajectory = time_optimal_trajectory(move.waypoints, move.dynamics, move.forbidden,
                                             limits)
        move.results[key] = trajectory.duration_s
        out[f'{label} s'] = f'{trajectory.duration_s:.3f}'
    return out


def ideal_supply(arm):
    """The arm on a perfect supply: no current limits, no battery resistance."""
    joints = {j.name: dataclasses.replace(j, current_limit_a=math.inf) for j in arm.joints}
    battery = dataclasses.replace(arm.battery, resistance_ohm=0.0)
    return dataclasses.replace(arm, battery=battery, **joints)


def column_ideal_supply(move: Move) -> dict:
    """The controller's limits on an ideal supply: what the electrical limits cost."""
    arm = ideal_supply(move.arm)
    trajectory = time_optimal_trajectory(move.waypoints, ArmDynamics(arm), move.forbidden,
                                         TrajectoryLimits.from_config(arm, move.controller))
    return {'ideal supply s': f'{trajectory.duration_s:.3f}'}


def column_minimum_time(move: Move) -> dict:
    """Direct collocation on 25, 50, 100 knots under the electrical limits: the time must
    settle (last change ≤ 0.5 %)."""
    guess = ocp.guess_from(move.trajectory, move.arm)
    begin = time.perf_counter()
    times, _ = ocp.refined_minimum(move.arm, move.start_q, move.waypoints[-1], guess)
    solve_s = time.perf_counter() - begin
    best = times[-1]
    move.results['minimum_s'] = best
    out = {f'min N={n}': (f'{t:.4f}' if math.isfinite(t) else 'fail')
           for n, t in zip(ocp.KNOTS, times)}
    change = abs(times[-1] - times[-2]) / times[-1]
    out['last change'] = f'{100 * change:.2f} %' + ('' if change <= ocp.CONVERGED else ' (!)')
    out['solve s'] = f'{solve_s:.1f}'
    for key, label in (('traj_s', 'traj/min'), ('unshaped_s', 'unshaped/min'),
                       ('half_reserve_s', 'half reserve/min'),
                       ('no_reserve_s', 'no reserve/min')):
        out[label] = f'{move.results[key] / best:.3f}'
    return out


def column_preempted(move: Move) -> dict:
    """Halfway through, a new goal (back to the start point): replan from the moving state."""
    half = 0.5 * move.trajectory.duration_s
    q, qd, _ = move.trajectory.sample(half)
    waypoints = _joint_path(move, q, move.start_xy)
    try:
        trajectory, cpu_ms, wall_ms = timed(lambda: time_optimal_trajectory(
            waypoints, move.dynamics, move.forbidden, move.limits, start_velocity_rad_s=qd))
    except TrajectoryError as error:
        return {'preempt |q̇| rad/s': f'{np.linalg.norm(qd):.2f}', 'preempt s': 'none',
                'preempt ms cpu/wall': str(error)}
    cells = _electrical_cells(move.arm, trajectory, 'preempt ')
    return {'preempt |q̇| rad/s': f'{np.linalg.norm(qd):.2f}',
            'preempt s': f'{trajectory.duration_s:.3f}',
            'preempt ms cpu/wall': f'{cpu_ms:.1f}/{wall_ms:.0f}',
            'preempt peak V': cells['preempt peak V'],
            'preempt min bus V': cells['preempt min bus V'],
            'preempt peak A': cells['preempt peak A']}


COLUMNS = [column_path, column_trajectory, column_unshaped, column_reserves,
           column_ideal_supply, column_minimum_time, column_preempted]


def _heights(arm, q):
    """Lowest y of the elbow and the tool for each configuration (m)."""
    upper, fore = arm.shoulder.length_m, arm.elbow.length_m
    elbow_y = upper * np.sin(q[:, 0])
    return np.minimum(elbow_y, elbow_y + fore * np.sin(q[:, 0] + q[:, 1]))


def print_table(rows):
    keys = list(dict.fromkeys(k for row in rows for k in row))
    print('| ' + ' | '.join(keys) + ' |')
    print('|' + '---|' * len(keys))
    for row in rows:
        print('| ' + ' | '.join(str(row.get(k, '')) for k in keys) + ' |')


def _moves(arm, controller, count=None):
    dynamics, forbidden = ArmDynamics(arm), ForbiddenSpace(arm)
    limits = TrajectoryLimits.from_config(arm, controller)
    for name, start_xy, goal_xy in SUITE[:count]:
        move = Move(name, start_xy, goal_xy, arm, controller, dynamics, forbidden, limits)
        plan_path(move)
        yield move


# --- the what-if table: current limits ------------------------------------------------

def with_current_limit(arm, limit_a):
    return dataclasses.replace(arm, **{j.name: dataclasses.replace(j, current_limit_a=limit_a)
                                       for j in arm.joints})


def what_if(count=None):
    """Per move and current limit: the timed trajectory against the electrical minimum."""
    base, controller = config.load('controller')
    rows = []
    for move in _moves(base, controller, count):
        row = {'move': move.name}
        for limit in WHAT_IF_LIMITS_A:
            arm = with_current_limit(base, limit)
            label = f'{limit:.0f} A' if math.isfinite(limit) else 'none'
            cells = [f'{label}: traj s / min s', f'{label}: ratio', f'{label}: bus V / A']
            row.update(dict.fromkeys(cells, ''))
            try:
                trajectory = time_optimal_trajectory(
                    move.waypoints, ArmDynamics(arm), move.forbidden,
                    TrajectoryLimits.from_config(arm, controller))
            except TrajectoryError:
                # No minimum either: the same arm cannot hold itself along the path.
                row[cells[0]] = 'cannot hold'
                continue
            times, _ = ocp.refined_minimum(arm, move.start_q, move.waypoints[-1],
                                           ocp.guess_from(trajectory, arm), knots=(50, 100))
            e = electrical(arm, trajectory)
            row[cells[0]] = f'{trajectory.duration_s:.3f} / {times[-1]:.3f}'
            row[cells[1]] = f'{trajectory.duration_s / times[-1]:.3f}'
            row[cells[2]] = (f'{e["min_bus_v"]:.1f} / {e["peak_a"]:.0f}'
                             + (' BROWNOUT' if e['brownout'] else ''))
        rows.append(row)
        print(' | '.join(f'{k}={v}' for k, v in row.items()), file=sys.stderr, flush=True)
    print('Timed trajectory (the controller limits) against the electrical minimum '
          '(direct collocation, 100 knots) at each per-motor current limit; bus V / A: the '
          "trajectory's lowest bus voltage and peak motor current")
    print_table(rows)


# --- the table ------------------------------------------------------------------------

def main(count=None):
    arm, controller = config.load('controller')
    rows = []
    limits = None
    for move in _moves(arm, controller, count):
        limits = move.limits
        row = {'move': move.name}
        for column in COLUMNS:
            row.update(column(move))
        rows.append(row)
        print(' | '.join(f'{k}={v}' for k, v in row.items()), file=sys.stderr, flush=True)
    print(f'trajectory limits: {limits.budget[0]:g} V driving, {limits.budget[1]:g} V '
          f'braking at the nominal bus, velocity {limits.max_velocity_rad_s} rad/s, '
          f'acceleration {limits.max_acceleration_rad_s2} rad/s^2, current limits '
          f'{[j.current_limit_a for j in arm.joints]} A per motor; minimum time under the '
          'same electrical limits (bus sag, current limits, brownout), free path')
    print_table(rows)
    ratios = [float(r['traj/min']) for r in rows]
    print(f'traj/min: worst {max(ratios):.3f}, median {statistics.median(ratios):.3f}')


if __name__ == '__main__':
    if '--what-if' in sys.argv:
        what_if()
    elif '--planning' in sys.argv:
        from planning_time import planning, PLANNING_REPEATS
        numbers = [a for a in sys.argv[1:] if a.isdigit()]
        planning(int(numbers[0]) if numbers else PLANNING_REPEATS)
    else:
        main(int(sys.argv[1]) if len(sys.argv) > 1 else None)
