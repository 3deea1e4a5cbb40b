"""``frc_robot_sim``: a stand-in for the roboRIO, with no ROS in it.

It serves NT4 on 127.0.0.1 only, steps the simulated arm (``ArmPlant``, noise and all) at
the robot loop's rate, and publishes the readings the contract names. It honours enable and
disable (``/arm/sim/enable``, as the Driver Station would). A command drives the motors
only until ``command_timeout_s`` after it was sent, then 0 V, however late the loop runs
(``CommandWatchdog``). Of the two kinds of command it applies the newest: voltages, or a
setpoint with feedforward closed by a PD loop here, as robot code would
(V = V_ff + kp·(θ_sp − θ) + kd·(θ̇_sp − θ̇), the controller's kp and kd). As in ``sim``, the
arm rests on its stow support until the first voltage that is not zero. The battery is
the plant's own: the battery sags, the motor controllers limit the current, as ``sim``'s.

    frc_robot_sim [--port PORT] [--params-file config/frc_robot.yaml ...]
"""

import argparse
from dataclasses import dataclass
import logging
import math
import signal
import sys
import threading

import ntcore

from arm_control import config
from arm_control.frc import contract as nt
from arm_control.frc.conversions import clamp_voltage, joint_pair
from arm_control.frc.rules import CommandWatchdog, ZERO_V
from arm_control.frc.settings import FrcRobotSimConfig, load_robot_sim
from arm_control.frc.tables import LOOPBACK, now_us, RobotTables
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.plant import ArmPlant
from arm_control.parameters import ParameterError

# After a stall (a paused process) the physics catches up at most this far, as the sim node.
MAX_CATCH_UP_S = 0.1
LOG_EVERY_S = 1.0           # the same complaint at most this often

log = logging.getLogger('frc_robot_sim')


@dataclass(frozen=True)
class VoltageCommand:
    voltage: tuple[float, float]


@dataclass(frozen=True)
class SetpointCommand:
    position: tuple[float, float]
    velocity: tuple[float, float]
    feedforward_v: tuple[float, float]


class RobotStandIn:
    """The robot loop: commands in, the arm stepped, readings out (call ``tick`` at 50 Hz)."""

    def __init__(self, arm: config.ArmConfig, sim: config.SimConfig,
                 robot: FrcRobotSimConfig, gains, port: int):
        self.arm = arm
        seed = None if sim.random_seed < 0 else sim.random_seed
        self.plant = ArmPlant(arm, sim.initial_position, sim.physics_step_s, seed)
        if sim.rest_until_first_command:
            self.plant.rest()
        self.motors = ArmDynamics(arm).motors
        self.gains = tuple((kp, kd) for kp, _, kd in gains)
        self.watchdog = CommandWatchdog(robot.command_timeout_s)
        self.enabled = robot.start_enabled
        self.tables = RobotTables(ntcore.NetworkTableInstance.create(), port)
        self.last_tick_s = None
        self.seen_us = {'voltage': 0, 'setpoint': 0, 'enable': 0}
        self.reading = self.plant.read()
        self.voltage = ZERO_V
        self.driving = False            # a command drove the motors at the end of the last loop
        self.complained_s = {}

    def complain(self, key: str, now_s: float, message: str) -> None:
        if now_s - self.complained_s.get(key, -math.inf) >= LOG_EVERY_S:
            self.complained_s[key] = now_s
            log.warning(message)

    # ------------------------------------------------------------------ inputs

    def take_enable(self, now_s: float) -> None:
        value = self.tables.enable.getAtomic()
        if value.time and value.time != self.seen_us['enable']:
            self.seen_us['enable'] = value.time
            if bool(value.value) != self.enabled:
                self.enabled = bool(value.value)
                log.info('enabled' if self.enabled else 'disabled: 0 V, commands ignored')
        if not self.enabled:
            self.watchdog.drop()

    def take_commands(self, now_s: float) -> None:
        """Offer the newest command of each kind to the watchdog, older kind first."""
        offers = []
        value = self.tables.voltage.getAtomic()
        if value.time and value.time != self.seen_us['voltage']:
            self.seen_us['voltage'] = value.time
            try:
                offers.append((value.time, VoltageCommand(joint_pair(
                    value.value, nt.VOLTAGE_COMMAND.name))))
            except ValueError as error:
                self.complain('voltage', now_s, f'refused: {error}')
        parts = [subscriber.getAtomic() for subscriber in self.tables.setpoint]
        sent_us = parts[0].time
        if sent_us and sent_us != self.seen_us['setpoint'] and \
                all(part.time == sent_us for part in parts):
            self.seen_us['setpoint'] = sent_us
            try:
                offers.append((sent_us, SetpointCommand(*(
                    joint_pair(part.value, topic.name)
                    for part, topic in zip(parts, nt.SETPOINT_COMMAND)))))
            except ValueError as error:
                self.complain('setpoint', now_s, f'refused: {error}')
        for sent_us, command in sorted(offers, key=lambda offer: offer[0]):
            if not self.enabled:
                continue
            refused = self.watchdog.offer(command, sent_us * 1e-6, now_s)
            if refused and 'not newer' not in refused:
                self.complain('stale', now_s, f'refused a command: {refused}')

    def voltage_for(self, command) -> tuple[float, float]:
        if command is None:
            return ZERO_V
        if isinstance(command, VoltageCommand):
            return clamp_voltage(command.voltage, self.arm.battery.nominal_voltage)
        position, velocity = self.reading.potentiometer_rad, self.reading.velocity_rad_s
        return clamp_voltage(
            [ff + kp * (q_sp - q) + kd * (qd_sp - qd) for ff, (kp, kd), q_sp, q, qd_sp, qd in zip(
                command.feedforward_v, self.gains, command.position, position,
                command.velocity, velocity)], self.arm.battery.nominal_voltage)

    # ------------------------------------------------------------------ the loop

    def tick(self, time_us: int) -> None:
        """One robot loop at ``time_us`` on NT's clock."""
        now_s = time_us * 1e-6
        start_s = now_s if self.last_tick_s is None else max(self.last_tick_s,
                                                             now_s - MAX_CATCH_UP_S)
        self.last_tick_s = now_s
        self.take_enable(now_s)
        self.take_commands(now_s)
        applied = []
        for from_s, to_s, command in self.watchdog.segments(start_s, now_s):
            if self.driving and command is None and self.enabled:
                self.complain('expired', now_s, f'no fresh command for '
                              f'{self.watchdog.timeout_s:g} s: 0 V')
            self.driving = command is not None
            self.voltage = self.voltage_for(command)
            if self.plant.resting and any(v != 0.0 for v in self.voltage):
                self.plant.release()
                log.info('first voltage: the arm leaves its rest')
            self.plant.set_voltage(self.voltage)
            self.plant.advance(to_s - from_s)
            applied.append((to_s, self.voltage))
        self.reading = self.plant.read()
        self.publish(time_us, applied)

    def publish(self, time_us: int, applied) -> None:
        reading, tables = self.reading, self.tables
        # The plant's electrical state: the bus, one motor's stator current per joint, the
        # battery's current (the PDH's convention: positive while drawing).
        bus_voltage_v, supply_a = reading.bus_voltage, reading.supply_current_a
        for to_s, voltage in applied:
            tables.publish(nt.APPLIED_VOLTAGE, list(voltage), round(to_s * 1e6))
        tables.publish(nt.ENABLED, self.enabled, time_us)
        tables.publish(nt.BUS_VOLTAGE, bus_voltage_v, time_us)
        tables.publish(nt.SUPPLY_CURRENT, supply_a, time_us)
        tables.publish(nt.MOTOR_CURRENT, [float(i) for i in reading.motor_current_a], time_us)
        tables.publish(nt.ENCODER, list(reading.encoder_rad), time_us)
        tables.publish(nt.VELOCITY, list(reading.velocity_rad_s), time_us)
        tables.publish(nt.POSITION, list(reading.potentiometer_rad), time_us)
        tables.true_state.set(list(reading.true_state), time_us)
        tables.instance.flush()

    def run(self, rate_hz: float, stop: threading.Event) -> None:
        """Tick at ``rate_hz`` on NT's clock until ``stop`` is set; a late loop does not
        burst to catch up."""
        period_us = round(1e6 / rate_hz)
        next_us = now_us()
        while not stop.is_set():
            self.tick(now_us())
            next_us += period_us
            late_us = now_us() - next_us
            if late_us > period_us:
                next_us = now_us()
            stop.wait(max(0.0, (next_us - now_us()) * 1e-6))

    def close(self) -> None:
        self.tables.close()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='frc_robot_sim', description=__doc__.split('\n')[0])
    parser.add_argument('--port', type=int, help='NT4 port on 127.0.0.1 (default: the '
                        "parameter file's frc_robot_sim nt_port)")
    parser.add_argument('--params-file', action='append', default=[],
                        help='parameter file layered over the installed config/arm.yaml '
                             '(repeatable)')
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format='[%(levelname)s] [%(name)s]: %(message)s')
    try:
        arm, sim = config.load('sim', *args.params_file)
        controller = config.load('controller', *args.params_file)[1]
        robot = load_robot_sim(*args.params_file)
        port = robot.nt_port if args.port is None else args.port
        stand_in = RobotStandIn(arm, sim, robot, (controller.shoulder_pid, controller.elbow_pid),
                                port)
    except (ParameterError, OSError) as error:
        log.critical(f'cannot start: {error}')
        return 2
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    log.info(f'serving NT4 on {LOOPBACK}:{port}; the arm at {list(sim.initial_position)} rad, '
             f"{'enabled' if robot.start_enabled else 'disabled'}, "
             f'{robot.loop_rate_hz:g} Hz loop')
    try:
        stand_in.run(robot.loop_rate_hz, stop)
    finally:
        stand_in.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
