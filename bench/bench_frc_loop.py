"""The arm on a robot's clock, over NT4: goals, whole readings, transit, disable and drops,
at robot-loop phases spread over the period, idle and beside two busy processes.

The robot is ``frc_robot_sim``'s loop (``RobotStandIn``: a real ntcore NT4 server running
the loop docs/frc_bridge.md prescribes) in this process, so what it published and when
commands reached it are known exactly; ``frc_bridge``, ``controller`` and ``planner`` run as
installed processes on their own ROS domain. The loop's phase is changed while everything
runs, as it drifts over a match. For each phase:

- goals: the presets in turn, each reached (the controller says so) and then held 2 s on
  the robot's truth: slowest joint under 0.1 rad/s, swing under 0.5°;
- mixed readings: ``joint_states`` and ``battery_state`` whose fields are not all those of
  the one reading the robot published at their stamp;
- transit: a reading from its sensors' instant to ``joint_states`` heard by another ROS
  process; a command from the bridge setting it to the robot's NT (the NT value's time);
- disabled: the robot disabled -> its first reading at 0 V and disabled, and ``arm_state``
  ``disabled`` heard on ROS;
- drop: the robot's NT server stopped -> the bridge says it lost the robot; served again
  -> the bridge says it is back. A "lost" outside these drops (and not within 0.3 s after
  the robot itself stalled for over 0.1 s) is false.

The reference row applies each command the moment it reaches the robot (as the default
``sim`` does), the loop still reading and publishing at its instants.

    python bench/bench_frc_loop.py                      # idle and busy, 4 phases
    python bench/bench_frc_loop.py --loads idle --phases-ms 0 10 --write-docs

Times on this shared machine are noisy; NT's clock and ROS's are both the system clock
here, which the transit figures rely on. Needs the package built and sourced.
"""

import argparse
import os
from pathlib import Path
import sys
import tempfile
import threading
import time

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / 'test' / 'rigs'), str(HERE.parent), str(HERE)]

from frc_loop_measures import (bridge_reading_ages, controller_hearing,  # noqa: E402
                               mixed_readings, others_realtime_cores, others_realtime_ticks,
                               percentiles, robot_stalls, stamp_s, transit_segments)
from geometry_msgs.msg import PointStamped  # noqa: E402
import numpy as np  # noqa: E402
from sensor_msgs.msg import BatteryState, JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray, String  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.frc.codec import ProfileCommand  # noqa: E402
from arm_control.frc.robot_sim import RobotStandIn  # noqa: E402
from arm_control.frc.settings import load_robot_sim  # noqa: E402
from arm_control.frc.tables import free_port, now_us  # noqa: E402
from arm_control.model.dynamics import ArmDynamics  # noqa: E402
from arm_control.nodes.common import COMMANDS, controller_sees_planner, LATCHED  # noqa: E402
from arm_control.realtime import raise_dds_threads, raise_process  # noqa: E402

GOALS = ('mid_score', 'high_score', 'back_score')
HOLD_S, HOLD_SPEED_RAD_S, HOLD_SWING_RAD = 2.0, 0.1, np.radians(0.5)
REACH_TIMEOUT_S = 20.0
PROBE_PRIORITY = 30                 # SCHED_FIFO of the probe's threads (the robot's: 50)
PROBE_DDS_PRIORITY = 1              # ... of its DDS threads: the controller's for its own
# Python hands its lock to a waiting thread after this long: the robot's NT threads time a
# command's arrival in this process and wait for the lock behind the probe or the robot's loop
# (Python's default, 5 ms, is the size of the commands' bar; a robot in Java or C++ has none).
SWITCH_INTERVAL_S = 0.0005


class Robot:
    """The stand-in, run on its own thread, with what it published and what reached it."""

    def __init__(self, port: int):
        arm, sim = config.load('sim')
        self.dynamics = ArmDynamics(arm)
        self.stand_in = RobotStandIn(arm, sim, load_robot_sim(), port)
        self.published = {}             # time_us -> Reading
        self.truth = []                 # (t_s, [q, q, qd, qd])
        self.arrivals = []              # (reached the robot µs, set by the bridge µs)
        self.stand_in.observer = self.observe
        self.taken = []                 # (loop instant s, the profile's setpoint-0 instant s)
        take = self.stand_in.arrived

        def arrived(now_s):
            commands = take(now_s)
            self.taken += [(now_s, c.time_us * 1e-6) for c in commands
                           if isinstance(c, ProfileCommand)]
            return commands
        self.stand_in.arrived = arrived
        import ntcore
        tables = self.stand_in.tables
        self.listener = tables.instance.addListener(
            tables.command, ntcore.EventFlags.kValueRemote,
            lambda event: self.arrivals.append((now_us(), event.data.value.time())))
        # As frc_robot_sim runs: its loop and ntcore's threads at real-time priority; this
        # (main) thread back to normal, so that what it starts is not real-time.
        self.problem = raise_process(load_robot_sim().realtime_priority)
        if self.problem:
            print(self.problem)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.stand_in.run, args=(self.stop,))
        self.thread.start()
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))

    def observe(self, reading, truth) -> None:
        self.published[reading.time_us] = reading
        self.truth.append((reading.time_us * 1e-6, truth))

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        self.stand_in.tables.instance.removeListener(self.listener)
        self.stand_in.close()


class Coprocessor:
    """frc_bridge, controller and planner as processes, and a probe of what they say."""

    def __init__(self, domain: int, port: int, log_dir: Path):
        from ros_harness import NodeProcess, Probe
        self.probe = Probe(domain, 'bench_frc_loop')
        # Its DDS threads (they receive what it hears) at the controller's priority for its
        # own: at normal priority under load they wait in the run queue, and the transit
        # measured would be theirs, not the bridge's.
        self.priority_problem = raise_dds_threads(PROBE_DDS_PRIORITY)
        if self.priority_problem:
            print(self.priority_problem)
        self.nodes = [NodeProcess('frc_bridge', domain, ['-p', f'nt_port:={port}'], log_dir),
                      NodeProcess('planner', domain, (), log_dir),
                      NodeProcess('controller', domain, (), log_dir)]
        node = self.probe.node
        self.heard = {name: [] for name in ('joint_states', 'battery', 'events', 'states',
                                            'controller_events', 'diagnostics')}
        from diagnostic_msgs.msg import DiagnosticArray
        # joint_states with DDS's times: (heard, message, published by the bridge, received).
        self.joint_states = []
        node.create_subscription(JointState, '/joint_states', self._keep_timed, 50)
        for name, msg_type, topic, qos in (
                ('battery', BatteryState, '/battery_state', 50),
                ('events', String, '/frc_bridge/events', 100),
                ('states', String, '/arm_state', LATCHED),
                ('controller_events', String, '/controller/events', 100),
                ('diagnostics', DiagnosticArray, '/diagnostics', 50)):
            node.create_subscription(msg_type, topic, self._keep(self.heard[name]), qos)
        self.goal_pub = node.create_publisher(PointStamped, '/goal_point', COMMANDS)
        # When the controller published each command (DDS's source time, on NT's clock).
        self.nt_minus_wall_us = now_us() - time.time() * 1e6
        self.commanded_us = []
        node.create_subscription(
            Float64MultiArray, '/voltage_command', lambda _, info: self.commanded_us.append(
                1e-3 * info['source_timestamp'] + self.nt_minus_wall_us), COMMANDS)

    def _keep_timed(self, message, info) -> None:
        heard = time.time()
        self.heard['joint_states'].append((heard, message))
        self.joint_states.append((heard, stamp_s(message.header),
                                  1e-9 * info['source_timestamp'],
                                  1e-9 * info['received_timestamp']))

    @staticmethod
    def _keep(into):
        return lambda message: into.append((time.time(), message))

    def said(self, name: str, words: str, since_s: float) -> list:
        return [t for t, m in self.heard[name] if t >= since_s and words in m.data]

    @property
    def state(self) -> str:
        return self.heard['states'][-1][1].data if self.heard['states'] else ''

    def ready(self) -> bool:
        def sees_planner():
            seen = [controller_sees_planner(m) for _, m in self.heard['diagnostics']]
            seen = [s for s in seen if s is not None]
            return bool(seen and seen[-1]) and self.state in ('waiting', 'holding')
        return self.probe.spin_until(sees_planner, 60.0)

    def close(self) -> None:
        for process in self.nodes:
            process.stop()
        self.probe.close()


def goal(copro, robot, name, x, y) -> dict:
    since = time.time()
    message = PointStamped()
    message.header.frame_id = 'arm_base'
    message.point.x, message.point.y = float(x), float(y)
    copro.goal_pub.publish(message)
    reached = bool(copro.probe.spin_until(
        lambda: copro.said('controller_events', 'reached', since), REACH_TIMEOUT_S))
    move_s = (copro.said('controller_events', 'reached', since) or [np.nan])[0] - since
    copro.probe.spin_for(HOLD_S + 0.1)
    from_s = time.time() - HOLD_S
    held = np.array([s for t, s in robot.truth if t > from_s])
    speed = np.max(np.abs(held[:, 2:])) if len(held) else np.inf
    swing = np.max(np.ptp(held[:, :2], axis=0)) if len(held) else np.inf
    volts = np.array([r.applied_voltage_v for us, r in list(robot.published.items())
                      if us * 1e-6 > from_s]).reshape(-1, 2)
    # Where in the hold the swing was: its first 0.5 s (the end of settling) or after.
    later = np.array([s for t, s in robot.truth if t > from_s + 0.5])
    swing_later = np.max(np.ptp(later[:, :2], axis=0)) if len(later) else np.inf
    return {'name': name, 'reached': reached, 'move_s': move_s, 'speed': speed,
            'swing': swing, 'swing_later': swing_later, 'held': reached and
            speed < HOLD_SPEED_RAD_S and swing < HOLD_SWING_RAD,
            'volts_ptp': np.ptp(volts, axis=0) if len(volts) else ()}


def disable(copro, robot) -> tuple[float, float]:
    """(ms to the robot's first reading disabled at 0 V, ms to arm_state disabled)."""
    since = time.time()
    robot.stand_in.enabled = False
    copro.probe.spin_until(lambda: copro.state == 'disabled', 3.0)
    to_state = next((t for t, m in copro.heard['states'] if t >= since and
                     m.data == 'disabled'), np.nan) - since
    first = min((us * 1e-6 for us, r in list(robot.published.items()) if us * 1e-6 >= since
                 and not r.enabled and r.applied_voltage_v == (0.0, 0.0)), default=np.nan)
    robot.stand_in.enabled = True
    copro.probe.spin_until(lambda: copro.state in ('waiting', 'holding'), 5.0)
    copro.probe.spin_for(1.0)
    return 1e3 * (first - since), 1e3 * to_state


def drop(copro, robot) -> tuple[float, float, tuple]:
    """(ms to 'lost', ms from serving again to 'back', the drop's window)."""
    since = time.time()
    robot.stand_in.tables.stop_serving()
    copro.probe.spin_until(lambda: copro.said('events', 'lost the robot', since), 2.0)
    lost = (copro.said('events', 'lost the robot', since) or [np.nan])[0] - since
    copro.probe.spin_for(1.0)
    served = time.time()
    robot.stand_in.tables.serve()
    copro.probe.spin_until(lambda: copro.said('events', 'robot back', served), 5.0)
    back = (copro.said('events', 'robot back', served) or [np.nan])[0] - served
    copro.probe.spin_until(lambda: copro.state in ('waiting', 'holding'), 10.0)
    copro.probe.spin_for(1.0)
    return 1e3 * lost, 1e3 * back, (since, time.time())


def run_phase(copro, robot, phase_ms, presets, load, reference=False) -> str:
    """One row: at ``phase_ms``, or (``reference``) with commands applied on arrival."""
    robot.stand_in.phase_s = phase_ms * 1e-3
    robot.stand_in.apply_on_arrival(reference)
    copro.probe.spin_for(1.0)
    since = time.time()
    others_from = others_realtime_ticks()
    arrivals_from, taken_from = len(robot.arrivals), len(robot.taken)
    moves = [goal(copro, robot, name, *presets[name]) for name in GOALS]
    mixed, checked, stamp_error_ms = mixed_readings(copro, robot, since)
    bridge_p50, bridge_over = bridge_reading_ages(copro, since)
    legs = transit_segments(copro, since)
    transit_in = legs['total']
    legs_p99 = ' / '.join(f'{np.percentile(legs[leg], 99):.1f}' if len(legs[leg]) else '-'
                          for leg in ('bridge', 'dds', 'probe'))
    print(f'phase {phase_ms} {load}: ' + ', '.join(
        f'{leg} {percentiles(ms)} max {np.max(ms, initial=0):.1f}' for leg, ms in legs.items()),
        file=sys.stderr)
    for m in moves:
        print(f"  {m['name']}: move {m['move_s']:.2f} s, held speed {m['speed']:.3f}, "
              f"swing {np.degrees(m['swing']):.2f} deg (after its first 0.5 s "
              f"{np.degrees(m['swing_later']):.2f}), reached {m['reached']}, applied V range "
              f"{np.round(m['volts_ptp'], 2)}", file=sys.stderr)
    arrivals = robot.arrivals[arrivals_from:]
    transit_out = [1e-3 * (arrived - sent) for arrived, sent in arrivals]
    # The leg before: the controller's publish to the bridge setting it on NT (the latest
    # command published before each one set; 0.5 ms of slack for the clocks' reading).
    published = np.sort(copro.commanded_us)
    before = np.searchsorted(published, [sent + 500.0 for _, sent in arrivals]) - 1
    to_bridge = [1e-3 * (sent - published[i]) for (_, sent), i in zip(arrivals, before)
                 if i >= 0]
    print(f'phase {phase_ms} {load}: commands controller -> bridge set '
          f'{percentiles(to_bridge)} max {max(to_bridge, default=0):.1f}, bridge set -> '
          f'robot {percentiles(transit_out)} max {max(transit_out, default=0):.1f}',
          file=sys.stderr)
    # A profile taken at a loop more than half a period after its setpoint 0's instant came
    # too late for it (the loop plays the setpoint nearest its instant).
    taken = robot.taken[taken_from:]
    period_s = 1.0 / robot.stand_in.robot.loop_rate_hz
    late = sum(loop_s > start_s + 0.5 * period_s for loop_s, start_s in taken)
    late_text = '-' if reference else f'{late}/{len(taken)}'     # on arrival: not queued
    goals_until = time.time()
    others_cores = others_realtime_cores(others_from, others_realtime_ticks(),
                                         goals_until - since)
    to_zero_ms, to_disabled_ms = disable(copro, robot)
    lost_ms, back_ms, window = drop(copro, robot)
    stalls = robot_stalls(robot, since)
    controller_age_ms, controller_lost = controller_hearing(copro, since, goals_until, window)
    false_lost = [(t, m.data) for t, m in copro.heard['events'] if t >= since and
                  'lost the robot' in m.data and not window[0] <= t <= window[1] and
                  not any(a <= t <= b + 0.3 for a, b in stalls)]
    loops = np.array(sorted(us * 1e-6 for us in list(robot.published)))
    for t, said in false_lost:
        before = loops[(loops > t - 0.3) & (loops <= t)]
        gap_ms = 1e3 * np.max(np.diff(before), initial=0.0)
        print(f"false lost at {t - since:.2f} s: {said}; the robot loop's longest gap in the "
              f'0.3 s before: {gap_ms:.0f} ms', file=sys.stderr)
    false_lost = len(false_lost)
    held = sum(m['held'] for m in moves)
    robot.stand_in.apply_on_arrival(False)
    phase = 'on arrival (reference)' if reference else f'{phase_ms:g}'
    return (f'| {load} | {others_cores:.2f} | {phase} | {held}/{len(moves)} | '
            f"{max(m['move_s'] for m in moves):.2f} | {max(m['speed'] for m in moves):.3f} | "
            f"{np.degrees(max(m['swing'] for m in moves)):.2f} | {mixed}/{checked} | "
            f'{stamp_error_ms:.2f} | {bridge_p50:.1f} / {bridge_over:.1f} | '
            f'{percentiles(transit_in)} | {legs_p99} | {controller_age_ms:.0f} | '
            f'{controller_lost} | {percentiles(transit_out)} | '
            f'{late_text} | {to_zero_ms:.0f} | '
            f'{to_disabled_ms:.0f} | {lost_ms:.0f} | {back_ms:.0f} | {false_lost} | '
            f'{len(stalls)} |')


HEADER = ("| load | others' real-time threads, cores | phase ms | goals reached & held | "
          'slowest move s | hold: fastest joint rad/s | hold: swing deg | mixed readings | '
          'stamp error ms | reading → bridge p50 ms / % over 10 ms | reading → joint_states '
          'heard p50 / p99 ms | its p99 legs: bridge / DDS / probe ms | controller: oldest '
          'joint_states ms | controller: sensors lost | '
          'command → robot p50 / p99 ms | profiles taken after their instant | '
          'disabled → 0 V ms | disabled → arm_state ms | '
          'drop → lost ms | served → back ms | false lost | robot stalls > 0.1 s |\n'
          '|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|'
          '---|')


def set_priority(priority: int, thread_id: int = 0) -> None:
    """A thread (0: this one) at SCHED_FIFO ``priority``, or normal scheduling for 0 (what
    it starts inherits it)."""
    os.sched_setscheduler(thread_id, os.SCHED_FIFO if priority else os.SCHED_OTHER,
                          os.sched_param(priority))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--phases-ms', type=float, nargs='+', default=[0.0, 5.0, 10.0, 15.0])
    parser.add_argument('--loads', nargs='+', default=['idle', 'busy'],
                        choices=['idle', 'busy'])
    parser.add_argument('--no-reference', dest='reference', action='store_false',
                        help='leave out the row with commands applied on arrival')
    parser.add_argument('--write-docs', action='store_true')
    args = parser.parse_args()
    import busy
    from ros_harness import ros_domain
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    presets = {name: (x, y) for name, x, y in config.load('sim')[0].presets}
    rows = []
    port = free_port()
    with ros_domain() as domain, tempfile.TemporaryDirectory() as log_dir:
        robot = Robot(port)
        copro = Coprocessor(domain, port, Path(log_dir))
        # The probe's spinning (this thread) a little below the robot's loop but real-time,
        # as the controller's executor: at normal priority, preempted while holding Python's
        # lock, it would stall the robot's loop in this process. Its DDS threads, the nodes'
        # processes and the busy loops are started at normal priority.
        probe_rt = not robot.problem
        set_priority(PROBE_PRIORITY if probe_rt else 0)
        try:
            if not copro.ready():
                raise SystemExit('the controller never became ready:\n' +
                                 copro.nodes[2].output()[-3000:])
            for load in args.loads:
                set_priority(0)                 # the busy loops at normal priority
                loops = busy.start(2, 900.0) if load == 'busy' else []
                set_priority(PROBE_PRIORITY if probe_rt else 0)
                if any(os.sched_getscheduler(p.pid) != os.SCHED_OTHER for p in loops):
                    busy.stop(loops)
                    raise SystemExit('the busy loops are not at normal priority')
                try:
                    runs = [(0.0, True)] * args.reference + \
                        [(phase_ms, False) for phase_ms in args.phases_ms]
                    for phase_ms, reference in runs:
                        rows.append(run_phase(copro, robot, phase_ms, presets, load, reference))
                        print(rows[-1], flush=True)
                finally:
                    busy.stop(loops)
        finally:
            copro.close()
            robot.close()
    table = HEADER + '\n' + '\n'.join(rows)
    print('\n' + table)
    if args.write_docs:
        import docs_table
        command = 'python bench/bench_frc_loop.py ' + ' '.join(sys.argv[1:])
        print(docs_table.write('frc_loop', "The arm on a robot's clock over NT4", command,
                               table))


if __name__ == '__main__':
    main()
