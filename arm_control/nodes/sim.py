"""The ``sim`` node: voltage commands in, the arm's sensors and its electrical state out.

Subscribes ``voltage_command`` (Float64MultiArray [shoulder_V, elbow_V]) and ``~/set_state``
(JointState by joint name: put the arm at a position and velocity); publishes
``joint_states`` (potentiometers), ``motor_encoders``, ``~/ground_truth``, ``battery_state``
(BatteryState: bus volts, supply current negative while discharging), ``motor_currents``
([shoulder_A, elbow_A], one motor of each joint), ``~/events`` (brownouts) and
``/diagnostics``; serves ``~/reset`` (Trigger: back to ``initial_position`` at rest).

``~/ground_truth`` carries the true state at ``ground_truth_rate_hz``: the samples since the
last reading go out with it, each stamped at its own instant, so that a move measured on
it is timed to a few milliseconds instead of to the reading period. (At 4× simulated time,
500 a second of wall time had a Python subscriber 2 s behind: the rate is of wall time.)

``command_timing: robot_loop`` (as a roboRIO): the sensors are read, and the latest command
that has arrived applied, only at the robot loop's instants, ``robot_loop_phase_s`` past each
whole period of the clock; a reading is stamped at its instant. ``on_arrival``: a command
acts from when it arrives (the physics brought up to that instant with the previous one
first). A command is a voltage pair or a profile the sim plays at the loop's instants on the
reading it takes there (``RobotCommands``, ``model/profile.py``). No plain command for
``command_timeout_s`` -> 0 V, as a disabled robot; a profile ends held. The
sim's own late ticks are not the robot's: up to ``MAX_CATCH_UP_S`` since the physics last
moved (a period and the usual jitter) is simulated with the command the robot had; the rest
of a longer stall of the sim (the process paused, or starved on a loaded machine) is a pause
of the whole world, and the arm goes on from where it was. The commands sent meanwhile were
on time for the robot: running the stall on the older one had driven the arm at full volts
where it should have braked, 200 mm into the floor. A stall of the controller alone is the
robot's: the sim goes on with its last command.

With ``sim_time_factor`` > 0 the sim owns time: it publishes ``/clock`` and advances the
physics one period per tick of a wall-clock timer ``sim_time_factor`` times faster than real
time; every other node runs with ``use_sim_time`` and follows it. It moves in step with the
controller: once commanded, a period begins only when the command for the last one has come
(or ``LOCKSTEP_WAIT_S`` of real time has passed), so a slow or paused process slows time
down instead of leaving the arm at 0 V. A command answers the period whose reading was out
before it was sent (its DDS source timestamp, on the one host's clock): one sent earlier is
late, for an earlier reading. It is applied, as a late command would be, but the period
still waits for its own. Counted as the answer, one late command (the first, sent while the
sim ran ahead of the controller) left every later one a period late, for good.
"""

import math
import statistics
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.time import Time
from rosgraph_msgs.msg import Clock as ClockMessage
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger

from arm_control import realtime
from arm_control.config import ArmConfig, JOINT_NAMES, SimConfig
from arm_control.model.plant import ArmPlant
from arm_control.model.profile import ProfileError
from arm_control.model.robot_commands import RobotCommands
from arm_control.nodes import messages
from arm_control.nodes.common import COMMANDS, declare_parameters, loop_statistics, run, status
from arm_control.nodes.sim_sensors import SensorTopics

# The physics catches up at most this much at once; the rest of a stall is a pause.
MAX_CATCH_UP_S = 0.03
# In simulated time, a period waits at most this long (real time) for the last one's command,
LOCKSTEP_WAIT_S = 0.5
# ... and begins no sooner than its wall time, less this (a timer's jitter).
WALL_SLACK_S = 0.0002


class SimNode(Node):

    def __init__(self):
        super().__init__('sim')
        params = declare_parameters(self, 'sim')
        self.arm = ArmConfig.from_parameters(params)
        self.config = SimConfig.from_parameters(params)
        seed = None if self.config.random_seed < 0 else self.config.random_seed
        self.plant = ArmPlant(self.arm, self.config.initial_position,
                              self.config.physics_step_s, seed)
        if self.config.rest_until_first_command:
            self.plant.rest()
        self.simulated_time = self.config.sim_time_factor > 0.0
        self.robot_loop = self.config.command_timing == 'robot_loop'
        self.commands = RobotCommands(self.arm.battery.nominal_voltage,
                                      self.config.command_timeout_s)
        self.period_s = 1.0 / self.config.publish_rate_hz
        self.wall_clock = Clock(clock_type=ClockType.STEADY_TIME)
        self.epoch_s = self.get_clock().now().nanoseconds * 1e-9   # sim time at plant time 0
        self.clock_origin_s = self.now_s()        # plant time 0: on the robot loop, an instant
        if self.robot_loop and not self.simulated_time:
            self.clock_origin_s = self.instant_s(self.clock_origin_s)
        self.last_command_s = -math.inf
        self.timed_out = True
        self.commands_rejected = self.commands_rejected_said = 0
        self.brownouts_said = 0
        self.brownouts_last_second = []
        self.periods_s, self.last_step_s = [], self.now_s()
        self.commanded_this_period = False
        self.reading_sent_ns = 0                  # system time the last reading went out
        self.late_commands = 0                    # sent before the period's reading
        self.command_transits_s = []              # from the controller's send to acting
        self.period_began_wall_s = self.wall_clock.now().nanoseconds * 1e-9
        self.period_due_wall_s = self.period_began_wall_s   # when the next period may begin

        self.sensors = SensorTopics(self)
        self.events_pub = self.create_publisher(String, '~/events', 100)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(Float64MultiArray, 'voltage_command', self.on_voltage, COMMANDS)
        self.create_subscription(JointState, '~/set_state', self.on_set_state, COMMANDS)
        self.create_service(Trigger, '~/reset', self.on_reset)
        # The rate is of wall time: faster than real time, as many messages a second (the
        # subscribers' load), fewer samples a simulated second.
        speed = max(1.0, self.config.sim_time_factor)
        self.truth_every = max(1, round(speed / (self.config.ground_truth_rate_hz
                                                 * self.plant.physics_step_s)))
        self.steps_to_truth = self.truth_every
        self.truths = []            # (plant s, stamp s, state, effort) since the last reading
        if self.simulated_time:
            self.clock_pub = self.create_publisher(ClockMessage, '/clock', 10)
            self.create_timer(self.period_s / self.config.sim_time_factor, self.step,
                              clock=self.wall_clock)
            self.create_timer(1.0 / self.config.sim_time_factor, self.publish_diagnostics,
                              clock=self.wall_clock)
        else:                   # a timer's phase is that of its creation: on the robot loop,
            now_s = self.now_s()    # read once: an instant may pass between two reads
            start_s = self.period_s if not self.robot_loop else \
                max(self.instant_s(now_s) + self.period_s - now_s, 0.0)
            self.starter = self.create_timer(start_s, self.start_stepping)
            self.create_timer(1.0, self.publish_diagnostics)
        priority = self.config.realtime_priority
        self.priority_problem = realtime.raise_this_thread(priority)   # the one that steps
        self.get_logger().info(
            f'simulating the arm at {self.config.publish_rate_hz:g} Hz from '
            f'[{self.config.initial_position[0]:.3f}, {self.config.initial_position[1]:.3f}] rad'
            f'{f" at real-time priority {priority}" if priority else ""}')
        if self.priority_problem:
            self.get_logger().warning(self.priority_problem)

    def now_s(self) -> float:
        if self.simulated_time:
            return self.epoch_s + self.plant.time_s
        return self.get_clock().now().nanoseconds * 1e-9

    def instant_s(self, t_s: float) -> float:
        """The robot loop's last instant at or before ``t_s`` (real time)."""
        phase = self.config.robot_loop_phase_s
        return phase + math.floor((t_s - phase) / self.period_s + 1e-6) * self.period_s

    def start_stepping(self) -> None:
        """The periodic step from now: at an instant of the robot loop when on it."""
        self.destroy_timer(self.starter)
        self.create_timer(self.period_s, self.step)
        self.step()

    def stamp(self):
        return Time(nanoseconds=round(self.now_s() * 1e9)).to_msg() if self.simulated_time \
            else self.get_clock().now().to_msg()

    def catch_up(self, now_s: float) -> None:
        """Bring the physics up to ``now_s`` with the command it has."""
        if self.simulated_time:
            return                                    # time is the physics' own
        behind_s = now_s - self.clock_origin_s - self.plant.time_s
        if behind_s > MAX_CATCH_UP_S:                 # the sim stalled: the world waited
            pause_s = behind_s - MAX_CATCH_UP_S
            if self.robot_loop:                       # whole periods: plant time 0 an instant
                pause_s = math.ceil(pause_s / self.period_s - 1e-9) * self.period_s
            self.clock_origin_s += pause_s
            self.commands.pair_s += pause_s           # the command aged with the world
            behind_s -= pause_s
        self.advance(math.floor(behind_s / self.plant.physics_step_s + 1e-3))

    @property
    def origin_s(self) -> float:
        """The clock's time at plant time 0."""
        return self.epoch_s if self.simulated_time else self.clock_origin_s

    def advance(self, steps: int) -> None:
        """``steps`` physics steps, the true state kept every ``truth_every`` of them."""
        origin_s = self.origin_s
        for _ in range(steps):
            self.plant.advance(self.plant.physics_step_s)
            self.steps_to_truth -= 1
            if self.steps_to_truth == 0:
                self.steps_to_truth = self.truth_every
                time_s = self.plant.time_s
                self.truths.append((time_s, origin_s + time_s, list(self.plant.state),
                                    self.plant.effort_nm()))

    def on_voltage(self, msg: Float64MultiArray, info: dict) -> None:
        try:
            command = messages.command_of(msg)
        except ProfileError as error:
            self.commands_rejected += 1
            self.get_logger().warning(
                f'rejected a voltage_command of {len(msg.data)} values: {str(error)[:300]}; '
                'expected [shoulder_V, elbow_V] or a profile (docs/robot_loop.md); keeping '
                'the last good command', throttle_duration_sec=1.0)
            return
        now = self.now_s()
        self.commands.arrive(now, command)
        if not self.robot_loop:                   # it acts now, on the sensors of now
            self.catch_up(now)
            self.commands.take(now)
            position = velocity = None            # a pair needs no reading
            if self.commands.playing:
                position, velocity = self.plant.sensors.potentiometers(self.plant.state[:2],
                                                                       self.plant.state[2:])
            self.apply(now, position, velocity)
        self.last_command_s = now
        self.command_transits_s.append((time.time_ns() - info['source_timestamp']) * 1e-9)
        if self.simulated_time and info['source_timestamp'] < self.reading_sent_ns:
            self.late_commands += 1
        else:
            self.commanded_this_period = True
        if self.timed_out:
            self.timed_out = False
            self.get_logger().info('voltage commands arriving')
        if self.simulated_time:     # the next period now, if its wall time has come
            self.step()

    def apply(self, t_s: float, position, velocity) -> None:
        """The commands' volts from ``t_s`` on the sensors' (q, q̇) of then; the first command
        taken releases the arm from its rest."""
        self.plant.set_voltage(self.commands.volts(t_s, position, velocity))
        if self.plant.resting and self.commands.taken:
            self.plant.release()
            self.get_logger().info('first voltage command: the arm leaves its rest')

    def on_set_state(self, msg: JointState) -> None:
        position = messages.joint_pair(msg, 'position')
        velocity = messages.joint_pair(msg, 'velocity') if msg.velocity else [0.0, 0.0]
        if position is None or velocity is None or not messages.finite(position + velocity):
            self.get_logger().warning(
                f'rejected set_state: expected finite positions (and optionally velocities) '
                f'of {list(JOINT_NAMES)}, by name or in that order; got names '
                f'{[n[:20] for n in msg.name[:4]]}, {len(msg.position)} positions',
                throttle_duration_sec=1.0)
            return
        self.catch_up(self.now_s())
        self.plant.reset(position, velocity)
        self.get_logger().info(f'arm set to position {position} rad, velocity {velocity} rad/s')

    def on_reset(self, request, response):
        self.catch_up(self.now_s())
        self.plant.reset(self.config.initial_position)
        self.plant.set_voltage((0.0, 0.0))
        self.commands = RobotCommands(self.arm.battery.nominal_voltage,
                                      self.config.command_timeout_s)
        if self.config.rest_until_first_command:
            self.plant.rest()
        response.success = True
        response.message = f'arm at rest at {list(self.config.initial_position)} rad'
        self.get_logger().info(response.message)
        return response

    def step(self) -> None:
        if self.simulated_time:
            wall_s = self.wall_clock.now().nanoseconds * 1e-9
            waiting = self.last_command_s > -math.inf and not self.commanded_this_period
            if waiting and wall_s - self.period_began_wall_s < LOCKSTEP_WAIT_S:
                return                        # the controller has not answered this period
            if waiting:
                self.get_logger().warning(
                    f'a period began without the command for the last: none for '
                    f'{LOCKSTEP_WAIT_S:g} s of real time ({self.late_commands} late commands '
                    'so far, each for an earlier reading)', throttle_duration_sec=5.0)
            if wall_s < self.period_due_wall_s - WALL_SLACK_S:
                return                        # its wall time has not come
            # Periods keep to the wall's schedule (a whole period late: a new one), so that a
            # period begun on a late command and the timer's tick it replaced, handled after
            # the next command, do not begin two periods at once.
            wall_period_s = self.period_s / self.config.sim_time_factor
            on_time = wall_s < self.period_due_wall_s + wall_period_s
            self.period_due_wall_s = (self.period_due_wall_s if on_time else wall_s) \
                + wall_period_s
            self.commanded_this_period, self.period_began_wall_s = False, wall_s
            self.advance(round(self.period_s / self.plant.physics_step_s))
        now = self.now_s()
        instant = self.instant_s(now) if self.robot_loop and not self.simulated_time else now
        stalled = now - self.last_step_s > 2.0 * self.period_s     # the sim's, not the robot's
        self.periods_s.append(now - self.last_step_s)
        self.last_step_s = now
        timeout_s = self.config.command_timeout_s
        if not stalled and now - self.last_command_s > timeout_s and not self.timed_out:
            self.timed_out = True
            self.get_logger().warning(f'no voltage_command for {timeout_s:g} s'
                                      + ('' if self.commands.playing else ': applying 0 V'))
            if not self.robot_loop and not self.commands.playing:
                self.catch_up(self.last_command_s + timeout_s)
                self.plant.set_voltage((0.0, 0.0))
        self.catch_up(instant)
        reading = self.plant.read()
        if self.robot_loop:
            self.commands.take(instant)
        self.apply(instant, reading.potentiometer_rad, reading.velocity_rad_s)
        self.say_brownouts()
        self.reading_sent_ns = time.time_ns()
        self.sensors.publish(reading, self.origin_s, self.truths)
        self.truths = []
        if self.simulated_time:     # after the reading: the controller's tick then finds it
            self.clock_pub.publish(ClockMessage(clock=self.stamp()))

    def say_brownouts(self) -> None:
        for brownout in self.plant.brownouts[self.brownouts_said:]:
            text = (f'brownout: the bus fell below {self.arm.battery.brownout_voltage:g} V for '
                    f'{brownout.duration_s:.3f} s (outputs at 0 V for {brownout.disabled_s:.3f} '
                    f's of it), from t = {brownout.start_s:.3f} s')
            self.events_pub.publish(String(data=text))
            self.get_logger().error(text)
            self.brownouts_last_second.append(brownout)
        self.brownouts_said = len(self.plant.brownouts)

    def publish_diagnostics(self) -> None:
        periods, self.periods_s = self.periods_s, []
        stats = loop_statistics(periods, [])
        transits, self.command_transits_s = self.command_transits_s, []
        brownouts, self.brownouts_last_second = self.brownouts_last_second, []
        level, message = DiagnosticStatus.OK, 'running'
        rejected_now = self.commands_rejected - self.commands_rejected_said
        self.commands_rejected_said = self.commands_rejected
        if rejected_now:
            level, message = DiagnosticStatus.WARN, f'{rejected_now} malformed voltage commands'
        if self.timed_out:
            level, message = DiagnosticStatus.WARN, 'no voltage commands: applying 0 V'
        if stats['worst'] > 3 * self.period_s:
            level, message = DiagnosticStatus.WARN, f'loop stalled for {stats["worst"]:.3f} s'
        if brownouts or self.plant.browned_out_since_s is not None:
            longest = max((b.duration_s for b in brownouts), default=0.0)
            level, message = DiagnosticStatus.ERROR, (
                f'brownout: {len(brownouts)} in the last second, the longest {longest:.3f} s'
                + ('; one going on' if self.plant.browned_out_since_s is not None else ''))
        power = self.plant.power
        diagnostic = DiagnosticArray()
        diagnostic.header.stamp = self.stamp()
        diagnostic.status = [status(self, level, message, {
            'mean period (s)': f'{stats["mean"]:.4f}', 'worst period (s)': f'{stats["worst"]:.4f}',
            'commands rejected': self.commands_rejected,
            'commands late for their period': self.late_commands,
            'profiles late for their first instant': self.commands.late,
            'command transit median (ms)': f'{1e3 * statistics.median(transits):.2f}'
                                           if transits else 'n/a',
            'command transit worst (ms)': f'{1e3 * max(transits):.2f}' if transits else 'n/a',
            'commanded voltage (V)': list(self.plant.command),
            'applied voltage (V)': [round(v, 3) for v in power.applied_v],
            'bus voltage (V)': f'{power.bus_voltage:.2f}',
            'brownouts': len(self.plant.brownouts),
        })]
        self.diagnostics_pub.publish(diagnostic)


def main(args=None):
    sys.exit(run(SimNode, args))


if __name__ == '__main__':
    main()
