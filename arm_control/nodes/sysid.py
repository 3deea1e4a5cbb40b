"""The ``sysid`` node: drives the arm through a safe excitation, logs it, fits the model.

Runs in place of the controller: it refuses to start while another node publishes
``voltage_command``, and stops if one appears. Subscribes ``joint_states`` (JointState) and
``battery_state`` (BatteryState, when the robot publishes it); publishes ``voltage_command``
(Float64MultiArray), one command for each joint state (at most twice ``loop_rate_hz``), and
``~/reference`` (JointState: the planned position and velocity each command was computed
for). It waits for the joint states, designs stage 1 of the excitation about ``centre_rad``
from where the arm is (checked clear of forbidden space and within the current before
anything moves), drives it, fits it while holding the arm at the centre, drives stage 2
with that fit's model, writes every sample to ``<output_directory>/log.mcap``, then fits
the whole log while holding the arm, writes ``identified_params.yaml``, ``report.md`` and
``fit.png`` there, and keeps holding the arm (with the identified model) until another node
commands it: then it stops publishing and exits (``sysid.handover``: it never leaves the arm
at 0 V while it can hold it). With ``fit_only_bag`` set it drives nothing: it fits that bag.
Exit code 0 when a parameter file was written, 1 otherwise. Its threads that receive and
send run at ``realtime_priority``; the fits at normal priority.
"""

from concurrent.futures import ThreadPoolExecutor
import math
import os
from pathlib import Path
import signal
import sys

import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.signals import uninstall_signal_handlers
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64MultiArray, Header

from arm_control import realtime
from arm_control.config import ArmConfig, JOINT_NAMES
from arm_control.nodes.common import COMMANDS, declare_parameters, interrupt, run, STATE_STREAM
from arm_control.nodes.messages import finite, joint_pair
from arm_control.sysid.handover import degrees, HandOver, holding_said
from arm_control.sysid.log import LogWriter, Samples
from arm_control.sysid.regressor import with_values
from arm_control.sysid.report import identify, said
from arm_control.sysid.session import provisional_model, Session
from arm_control.sysid.settings import SysIdConfig
from arm_control.sysid.wpilog import read_recording

# Joint states for this long before driving, so that other publishers show: DDS discovery
# took over 1 s on a loaded 2-core machine. Driving stops if one shows later.
DISCOVERY_S = 2.0
# A start it cannot excite from is refused only after this long: most often another node's
# commands moved the arm there, and that node's publisher can show later still (over 2 s on
# a loaded machine), so its reason is said instead.
UNSAFE_START_WAIT_S = 5.0
SHUTDOWN_ACK_S = 0.5        # at most this long on exit for the 0 V command to arrive
LOG_NAME = 'log.mcap'
COMMANDING = ('driving', 'fitting', 'holding', 'lowering')


def _normal_priority() -> None:
    """The fit worker runs at normal priority: it must not starve the beat or the machine."""
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except OSError:
        pass


def _velocity_since(sample, position, now):
    """The velocity from the last sample (received s, position, ...) to ``position`` now."""
    if sample is None or now <= sample[0]:
        return [0.0, 0.0]
    return list((np.array(position[:2]) - sample[1]) / (now - sample[0]))


def _stamp_s(msg) -> float | None:
    stamp = msg.header.stamp
    return stamp.sec + 1e-9 * stamp.nanosec if (stamp.sec or stamp.nanosec) else None


class SysIdNode(Node):

    def __init__(self):
        super().__init__('sysid')
        params = declare_parameters(self, 'sysid')
        self.arm = ArmConfig.from_parameters(params)
        self.settings = SysIdConfig.from_parameters(params)
        self.directory = Path(self.settings.output_directory)
        self.period_s = 1.0 / self.settings.loop_rate_hz
        self.exit_code = 1
        # waiting → driving → (stage-1 fit) → driving → fitting → holding [→ lowering] → done
        self.phase = 'waiting'
        self.handover = HandOver()
        self.joint_sample = None            # (received s, position, velocity)
        self.unsafe_start = None            # why the start cannot be excited from, when not
        self.first_joint_s = self.writer = self.session = self.label = self.work = None
        self.voltage_pub = self.hold_model = self.bus_v = None
        self.last_command_s = self.commanded_stamp_s = -math.inf
        self.samples = Samples()            # for stage 1's fit
        self.workers = ThreadPoolExecutor(max_workers=1, initializer=_normal_priority)
        if self.settings.fit_only_bag:
            self.create_timer(0.05, self.fit_only)
            self.get_logger().info(f'fitting {self.settings.fit_only_bag}; nothing is driven')
            return
        self.voltage_pub = self.create_publisher(Float64MultiArray, 'voltage_command',
                                                 COMMANDS)
        self.reference_pub = self.create_publisher(JointState, '~/reference', STATE_STREAM)
        self.create_subscription(JointState, 'joint_states', self.on_joint_states,
                                 STATE_STREAM)
        self.create_subscription(BatteryState, 'battery_state', self.on_battery, STATE_STREAM)
        self.create_subscription(Float64MultiArray, 'voltage_command', self.on_command,
                                 COMMANDS)
        self.create_timer(self.period_s, self.watch)
        self.writer = LogWriter(self.directory / LOG_NAME)   # ready before the arm moves
        problem = realtime.raise_process(self.settings.realtime_priority)
        if problem:
            self.get_logger().warning(problem)
        self.get_logger().info(
            'waiting for joint_states; the controller must not be running (this node '
            'drives the arm)')

    def now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # ------------------------------------------------------------------ inputs

    def on_joint_states(self, msg: JointState) -> None:
        position = joint_pair(msg, 'position')
        velocity = joint_pair(msg, 'velocity')
        if position is None or not finite(position):
            self.get_logger().warning(f'ignored joint_states: position {list(msg.position)} '
                                      'is not 2 finite angles', throttle_duration_sec=1.0)
            return
        now = self.now_s()
        if velocity is None or not finite(velocity):
            velocity = _velocity_since(self.joint_sample, position, now)
        self.joint_sample = (now, np.array(position[:2], float), np.array(velocity[:2], float))
        if self.first_joint_s is None:
            self.first_joint_s = now
        stamp = _stamp_s(msg) or now
        if self.writer is not None and self.phase != 'waiting':
            self.writer.joint_state(stamp, msg)
            self.samples.joint(stamp, *self.joint_sample[1:])
        # One command per joint state, so that each is computed from the freshest reading;
        # at most two a period of the sensor's time (a backlog after a stall is worked through
        # to its newest reading, not left at its oldest).
        if self.phase in COMMANDING and self.voltage_pub is not None and \
                stamp - self.commanded_stamp_s >= 0.5 * self.period_s:
            self.commanded_stamp_s = stamp
            self.drive(now)

    def on_command(self, msg: Float64MultiArray) -> None:
        """Every voltage_command, own ones too: another node's, a few, take the arm over."""
        if self.phase not in COMMANDING or self.voltage_pub is None:
            return
        self.handover.heard(msg.data)
        if self.handover.taken:
            self.hand_over()

    def hand_over(self) -> None:
        """Another node commands the arm: stop commanding (a fit under way still finishes)."""
        self.destroy_publisher(self.voltage_pub)
        self.voltage_pub = None
        self.get_logger().info('another node commands the arm: handed over')
        if self.phase == 'driving':
            self.finish('the excitation was interrupted by the other node: nothing fitted')
        elif self.phase != 'fitting':
            self.finish('handed over', error=self.exit_code != 0)

    def on_battery(self, msg: BatteryState) -> None:
        if not (math.isfinite(msg.voltage) and msg.voltage > 0.0):
            return
        self.bus_v = msg.voltage                # commands stay under it
        if self.writer is not None and self.phase != 'waiting':
            self.writer.battery(_stamp_s(msg) or self.now_s(), msg)

    # ------------------------------------------------------------------ the run

    def watch(self) -> None:
        """Start once the joint states flow; stop if they stop; pick up finished fits."""
        now = self.now_s()
        if self.phase == 'waiting':
            self.wait_then_start(now)
            return
        if self.phase not in COMMANDING:
            return
        if self.voltage_pub is not None and \
                now - self.joint_sample[0] > self.settings.joint_state_timeout_s:
            self.finish(f'no joint_states for {now - self.joint_sample[0]:.2f} s: stopped at '
                        '0 V')
            return
        if self.work is not None and self.work.done():
            self.take_work()
        if self.phase == 'holding' and self.handover.expired(
                now, self.settings.hand_over_timeout_s):
            self.lower()

    def wait_then_start(self, now) -> None:
        if self.first_joint_s is None or now - self.first_joint_s < DISCOVERY_S:
            return
        others = self.count_publishers('voltage_command') - 1
        if others > 0:
            self.finish(f'{others} other node(s) publish voltage_command (the controller?): '
                        'stop them first; nothing was driven')
            return
        if self.unsafe_start is None:
            try:
                self.session = Session(self.arm, self.settings, self.joint_sample[1])
            except ValueError as error:
                self.unsafe_start = str(error)      # said once other publishers had time
        if self.unsafe_start is not None:
            if now - self.first_joint_s >= UNSAFE_START_WAIT_S:
                self.finish(f'no safe excitation: {self.unsafe_start}')
            return
        for note in self.session.notes:
            self.get_logger().warning(f'excitation {note}')
        excitation = self.session.run.excitation
        self.get_logger().info(
            f'stage 1: {excitation.duration_s:.1f} s: '
            + ', '.join(part.name for part in excitation.parts))
        self.phase = 'driving'
        self.drive(self.now_s())

    def drive(self, now) -> None:
        _, position, velocity = self.joint_sample
        session = self.session
        if self.phase == 'driving' and session.stopped is None and \
                self.count_publishers('voltage_command') > 1:
            session.run.stop(now, position, 'another node began publishing voltage_command')
        stalls = len(session.stalls)
        voltage = session.command(now, position, velocity, self.bus_v)
        if len(session.stalls) > stalls:
            self.get_logger().warning(f'no command for {session.stalls[-1][1]:.2f} s (this '
                                      'process was starved): rejoining the excitation')
        self.publish(voltage, now)
        if self.phase == 'lowering' and session.run.finished(now):
            self.finish(f'lowered onto the rest at {degrees(self.settings.rest_rad)}: 0 V')
        if self.phase != 'driving':
            return
        self.say_where(now)
        if session.stage_one_done(now) and self.work is None:
            self.get_logger().info('stage 1 done: fitting it while holding the arm')
            self.work = self.workers.submit(provisional_model, self.samples.log(),
                                            self.arm, self.settings)
        elif session.finished(now):
            self.writer.close()
            self.writer = None
            if session.stopped is not None:
                self.get_logger().error(f'excitation stopped: {session.stopped}; fitting '
                                        'what it logged')
            self.get_logger().info(
                f'excitation done in {session.elapsed_s(now):.1f} s of arm time '
                f'({session.run.current_clamped} commands held to max_current_a in stage 2, '
                f'{len(session.stalls)} stalls ridden through); fitting while holding the arm')
            self.phase = 'fitting'
            self.work = self.workers.submit(self.identify, self.directory / LOG_NAME)

    def say_where(self, now) -> None:
        label, self.label = self.label, self.session.label_at(now)
        if label != self.label and self.session.stopped is not None:
            self.get_logger().error(f'excitation stopped: {self.session.stopped}; gliding '
                                    'back to the centre')
        elif label != self.label:
            self.get_logger().info(f'excitation: {self.label}')

    def publish(self, voltage, now) -> None:
        self.last_command_s = now
        data = [float(v) for v in voltage]
        self.handover.sent(data)
        self.voltage_pub.publish(Float64MultiArray(data=data))
        q_ref, qd_ref = self.session.reference
        reference = JointState(header=Header(stamp=self.get_clock().now().to_msg()),
                               name=list(JOINT_NAMES), position=[float(v) for v in q_ref],
                               velocity=[float(v) for v in qd_ref])
        self.reference_pub.publish(reference)
        if self.writer is not None:
            self.writer.voltage(now, voltage)
            self.writer.reference(now, q_ref, qd_ref)
            self.samples.command(now, voltage, q_ref)

    def take_work(self) -> None:
        work, self.work = self.work, None
        if self.phase == 'driving':
            try:
                model, note = work.result()
            except Exception as error:           # any failure: stage 2 with the file's model
                model, note = self.arm, f'stage 2 with the robot file: stage 1 gave {error}'
            known = len(self.session.notes)
            self.session.begin_stage_two(model, note)
            for line in self.session.notes[known:]:
                self.get_logger().info(f'excitation {line}')
            excitation = self.session.run.excitation
            self.get_logger().info(f'stage 2: {excitation.duration_s:.1f} s: '
                                   + ', '.join(part.name for part in excitation.parts))
            return
        try:
            result = work.result()
        except (ValueError, OSError) as error:
            self.hold(f'could not fit: {error}', self.arm)
            return
        self.report(result)

    def identify(self, bag):
        notes = self.session.notes if self.session is not None else []
        return identify(read_recording(bag, self.settings.wpilog_entries), self.arm,
                        self.settings, self.directory, str(bag), notes)

    def report(self, result) -> None:
        self.get_logger().info(said(result))
        if result.parameter_file is None:
            self.hold(f'no parameter file: {result.error}', self.arm)
            return
        self.exit_code = 0
        self.hold(f'wrote {result.parameter_file}: layer it over the robot file with '
                  f'--params-file {result.parameter_file}',
                  with_values(self.arm, result.realisation.values), error=False)

    def hold(self, message: str, model, error: bool = True) -> None:
        """Say how it ended; hold the arm where the plan ended until another node takes it."""
        (self.get_logger().error if error else self.get_logger().info)(message)
        if self.voltage_pub is None or self.session is None:      # handed over, or fit-only
            self.finish('done', error=error)
            return
        self.phase = 'holding'
        self.hold_model = model
        where = self.session.reference[0]
        self.session.hold(model, where)
        self.handover.hold_from(self.now_s())
        self.get_logger().info(holding_said(where, self.settings.hand_over_timeout_s,
                                            self.settings.rest_rad))

    def lower(self) -> None:
        try:
            self.session.lower(self.hold_model, self.joint_sample[1], self.settings.rest_rad)
            self.phase = 'lowering'
            self.get_logger().info('no other node took the arm: lowering it onto the rest')
        except ValueError as error:
            self.get_logger().error(f'cannot lower the arm: {error}; holding it')
            self.handover.holding_since_s = math.inf

    def fit_only(self) -> None:
        if self.phase == 'waiting':
            self.phase = 'fitting'
            self.work = self.workers.submit(self.identify, Path(self.settings.fit_only_bag))
        elif self.phase == 'fitting' and self.work.done():
            self.take_work()

    def finish(self, message: str, error: bool = True) -> None:
        """Say how it ended, send 0 V, and end spin()."""
        if self.phase == 'done':
            return
        self.phase = 'done'
        (self.get_logger().error if error else self.get_logger().info)(message)
        if self.writer is not None:
            self.writer.close()
            self.writer = None
        self.send_zero_volts()
        self.context.try_shutdown()          # ends spin(); main() cleans up

    def send_zero_volts(self) -> None:
        """0 V, only while this node commands the arm (never over another node's commands)."""
        if self.voltage_pub is None or not math.isfinite(self.last_command_s):
            return
        try:
            for _ in range(3):
                self.voltage_pub.publish(Float64MultiArray(data=[0.0, 0.0]))
            self.voltage_pub.wait_for_all_acked(Duration(seconds=SHUTDOWN_ACK_S))
        except Exception as error:              # the context may already be gone
            self.get_logger().warning(f'could not send 0 V: {error}')

    def on_shutdown(self) -> None:
        """0 V on the way out (Ctrl-C mid-run): the arm must not keep the last command."""
        self.workers.shutdown(wait=False, cancel_futures=True)
        if self.writer is not None:
            self.writer.close()
            self.writer = None
        if self.phase != 'done':
            self.send_zero_volts()


class _Started:
    node = None


def sysid_node() -> SysIdNode:
    """The node, with SIGINT and SIGTERM handed back to Python so that 0 V goes out first."""
    uninstall_signal_handlers()
    signal.signal(signal.SIGINT, interrupt)
    signal.signal(signal.SIGTERM, interrupt)
    _Started.node = SysIdNode()
    return _Started.node


def main(args=None):
    code = run(sysid_node, args)
    sys.exit(code or (_Started.node.exit_code if _Started.node is not None else 1))


if __name__ == '__main__':
    main()
