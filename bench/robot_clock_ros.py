"""``robot_clock.py --ros``: its rows through ROS, the three nodes started afresh per row.

Per row the sim runs with the row's ``command_timing`` and ``robot_loop_phase_s`` and the
controller with its ``command_mode`` (``bench_ros.nodes``, two busy loops beside them under
``--load``). The holds: the arm taken by a goal to each of ``robot_clock.HOLDS``, then 2 s of
``/sim/ground_truth``. The moves: ``bench_ros.RosMoves`` (to the start by a goal, at rest,
then the goal; timed on the true state). The minimum is the suite's from its nominal start
(``minimum_time`` cache): the starts through ROS lie within a degree of it.

Per move, from the probe (on the one host's clock): the sim's loop instants are the stamps
of its ``/joint_states`` (a reading per instant); the first at or after the goal's
publication is where the robot's loop lets a move start at the soonest (a command sent the
instant the goal was published, in no time, acts there). The move's start (``Start``): the
first profile that moves, when it reached the probe (DDS's receipt time, as it reaches the
sim: the same hop; the probe's callback may run later under load) and the instant the sim
played it from (the first at or after its arrival).
"""

import math
import sys

from bench_ros import lowest_mm, nodes, RosMoves
import minimum_time
import numpy as np
import robot_clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from arm_control import config
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.realtime import raise_dds_threads

HOLD_SETTLE_S = 1.0
# The probe's DDS threads at the controller's executor priority: at normal priority under
# load they wait in the run queue, and a command's arrival would be timed late.
PROBE_DDS_PRIORITY = 1
MOVING_RAD = 2e-4               # a profile moves: its setpoints' positions spread this far


def stamp_s(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


class Start:
    """The sim's loop instants and the profiles that reach it, for each move's start."""

    def __init__(self, rig):
        node = rig.probe.node
        self.instants, self.profiles = [], []   # stamps s; (arrived s, its setpoints' spread)
        node.create_subscription(JointState, '/joint_states',
                                 lambda msg: self.instants.append(stamp_s(msg)), 100)
        node.create_subscription(Float64MultiArray, '/voltage_command', self.on_command, 100)

    def on_command(self, msg, info) -> None:
        if len(msg.data) >= 12:         # received: the system clock, the clock of the stamps
            positions = np.reshape(msg.data[6:], (-1, 6))[:, :2]
            self.profiles.append((1e-9 * info['received_timestamp'],
                                  float(np.max(np.ptp(positions, axis=0)))))

    def first_instant(self, after_s: float) -> float:
        return min((t for t in self.instants if t >= after_s), default=math.nan)

    def of_move(self, published_s: float) -> tuple:
        """(the first loop instant at or after the goal's publication; the first moving
        profile's arrival; the instant it acted at), in s of the clock."""
        arrived = min((t for t, spread in self.profiles
                       if t >= published_s and spread > MOVING_RAD), default=math.nan)
        return self.first_instant(published_s), arrived, self.first_instant(arrived)


def node_args(row) -> dict:
    sim = ['-p', f'command_timing:={row.timing}']
    if math.isfinite(row.phase_ms):
        sim += ['-p', f'robot_loop_phase_s:={row.phase_ms / 1000.0:g}']
    return {'sim': tuple(sim), 'controller': ('-p', f'command_mode:={row.mode}')}


def hold(rig, ros, q):
    """(fastest joint rad/s, swing deg) over 2 s held at ``q``, taken there by a goal."""
    arm = config.load('sim')[0]
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    if ros.go_to(kinematics.forward(q)) is None:
        return math.nan, math.nan
    rig.spin_for(HOLD_SETTLE_S)
    since = rig.truth[-1][0]
    rig.spin_for(robot_clock.HOLD_S)
    held = [m for t, m in rig.truth if t > since]
    return float(np.max(np.abs([m.velocity for m in held]))), \
        float(np.degrees(np.max(np.ptp([m.position for m in held], axis=0))))


def run(args, rows, suite) -> str:
    arm, controller_config = config.load('controller')
    moves = [(name, robot_clock.start_configuration(arm, start), goal)
             for name, start, goal in suite]
    minimums = minimum_time.suite_minimums(arm, controller_config, moves, minimum_time.CACHE)
    for row in rows:
        with nodes('robot_clock', node_args(row), args.load, args.domain) as rig:
            rig.start_all()
            rig.ready(90.0)
            ros = RosMoves(rig, False)
            start = Start(rig)
            problem = raise_dds_threads(PROBE_DDS_PRIORITY)
            if problem:
                print(problem, file=sys.stderr)
            speeds, swings = zip(*(hold(rig, ros, q) for q in robot_clock.HOLDS))
            row.hold_speed, row.hold_swing_deg = max(speeds), max(swings)
            for name, start_xy, goal_xy in suite:
                for _ in range(args.repeats):
                    result = ros.move(goal_xy) if ros.go_to(start_xy) is not None else None
                    row.names.append(name)
                    if result is None or not math.isfinite(result['ros_s']):
                        row.failed.append(name)
                        row.ratios.append(math.nan)
                        row.loop_ratios += [math.nan] if row.timing == 'robot_loop' else []
                        continue
                    row.ratios.append(result['ros_s'] / minimums[name]['min_s'])
                    published = result['published_s']
                    loop_s, arrived_s, acted_s = start.of_move(published)
                    if row.timing == 'robot_loop':
                        row.loop_ratios.append((result['ros_s'] - (loop_s - published))
                                               / minimums[name]['min_s'])
                    row.to_robot_ms.append(1000.0 * (arrived_s - published))
                    if row.timing == 'robot_loop':
                        row.loop_wait_ms.append(1000.0 * (acted_s - arrived_s))
                    if len(result['q']):
                        row.lowest_mm = min(row.lowest_mm, lowest_mm(arm, result['q']))
        print(f'  {row.label} {robot_clock.fmt(row.phase_ms, ".0f")} ms: '
              f'{robot_clock.summary(row)}', file=sys.stderr, flush=True)
    return (f'through ROS ({"two busy loops beside" if args.load else "idle"}, a shared '
            f'machine; {args.repeats} run(s) a move; the minimum from each move' + "'s "
            'nominal start)')
