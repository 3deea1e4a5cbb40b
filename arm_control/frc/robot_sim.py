"""``frc_robot_sim``: a stand-in for the roboRIO, with no ROS in it.

It serves NT4 on 127.0.0.1 only and runs a robot loop as the contract says a robot does
(``robot_loop.RobotLoop``): at instants phase + k·period of the NT server clock it reads the
simulated arm's sensors (``ArmPlant``, noise and all), publishes them as one reading stamped
with that instant, and applies the newest command that has arrived: a voltage pair, or a
profile played on the fresh reading with the profile's own kp and kd. A voltage pair drives
the motors until its own instant + ``command_timeout_s``, then 0 V; a profile is played to
its end and then holds its last setpoint. It honours enable and disable
(``/arm/sim/enable``, as the Driver Station would). As in ``sim``, the arm rests on its stow
support until the first voltage that is not zero; the battery sags and the motor
controllers limit the current, as ``sim``'s.

    frc_robot_sim [--port PORT] [--phase-s PHASE] [--params-file config/frc_robot.yaml ...]
"""

import argparse
import logging
import math
import signal
import sys
import threading

import ntcore

from arm_control import config
from arm_control.frc.codec import decode_command, encode_reading
from arm_control.frc.robot_loop import loop_instants, RobotLoop
from arm_control.frc.settings import FrcRobotSimConfig, load_robot_sim
from arm_control.frc.tables import LOOPBACK, now_us, RobotTables
from arm_control.model.plant import ArmPlant
from arm_control.parameters import ParameterError
from arm_control.realtime import raise_process

LOG_EVERY_S = 1.0           # the same complaint at most this often

log = logging.getLogger('frc_robot_sim')


class RobotStandIn:
    """The robot loop over NT: commands in, the arm stepped, readings out (``tick`` at each
    loop instant, or ``run``)."""

    def __init__(self, arm: config.ArmConfig, sim: config.SimConfig,
                 robot: FrcRobotSimConfig, port: int):
        self.arm = arm
        self.robot = robot
        seed = None if sim.random_seed < 0 else sim.random_seed
        self.plant = ArmPlant(arm, sim.initial_position, sim.physics_step_s, seed)
        if sim.rest_until_first_command:
            self.plant.rest()
        self.loop = RobotLoop(self.plant, arm.battery.nominal_voltage,
                              robot.command_timeout_s)
        self.enabled = robot.start_enabled
        self.port = port
        self.tables = RobotTables(ntcore.NetworkTableInstance.create(), port)
        self.enable_seen_us = 0
        self.driving = False            # a command drove the motors after the last loop
        self.complained_s = {}
        self.phase_s = robot.loop_phase_s   # may change while it runs, as a match drifts
        self.observer = None            # observer(reading, true_state) after each loop
        self.lock = threading.Lock()    # the loop, and commands applied on arrival
        self.on_arrival = None          # the listener applying them, for a reference run

    @property
    def voltage(self) -> tuple[float, float]:
        return self.loop.voltage

    def complain(self, key: str, now_s: float, message: str) -> None:
        if now_s - self.complained_s.get(key, -math.inf) >= LOG_EVERY_S:
            self.complained_s[key] = now_s
            log.warning(message)

    def take_enable(self) -> None:
        value = self.tables.enable.getAtomic()
        if value.time and value.time != self.enable_seen_us:
            self.enable_seen_us = value.time
            if bool(value.value) != self.enabled:
                self.enabled = bool(value.value)
                log.info('enabled' if self.enabled else 'disabled: 0 V, commands ignored')

    def arrived(self, now_s: float) -> list:
        """Every command that arrived since the last loop, decoded, oldest first."""
        commands = []
        for value in self.tables.command.readQueue():
            try:
                commands.append(decode_command(value.value))
            except ValueError as error:
                self.complain('command', now_s, f'refused: {error}')
        return commands

    def apply_on_arrival(self, on: bool) -> None:
        """A reference, not a robot: commands applied the moment they arrive, as ``sim``
        does by default; the loop still reads and publishes at its instants."""
        instance = self.tables.instance
        if on and self.on_arrival is None:
            self.on_arrival = instance.addListener(
                self.tables.command, ntcore.EventFlags.kValueRemote, self._arrived)
        elif not on and self.on_arrival is not None:
            instance.removeListener(self.on_arrival)
            self.on_arrival = None

    def _arrived(self, event) -> None:
        """ntcore's listener thread: a command arrived; applied now (reference runs only)."""
        now_s = now_us() * 1e-6
        with self.lock:
            try:
                command = decode_command(event.data.value.getDoubleArray())
            except ValueError:
                return                          # the loop says so when it drains its queue
            self.loop.apply_on_arrival(now_s, self.enabled, [command])

    def tick(self, time_us: int) -> None:
        """One robot loop at ``time_us`` on the NT server clock."""
        with self.lock:
            self._tick(time_us)

    def _tick(self, time_us: int) -> None:
        now_s = time_us * 1e-6
        self.take_enable()
        arrived = self.arrived(now_s)
        if self.on_arrival is not None:
            arrived = []                        # taken on arrival already
        reading, truth = self.loop.step(now_s, self.enabled, arrived)
        for _, command in self.loop.refused:
            self.complain('stale', now_s, f'refused a command for '
                          f'{command.time_us * 1e-6 - now_s:+.3f} s: past its expiry')
        self.loop.refused.clear()
        driving = self.loop.driving
        if self.driving and not driving and self.enabled:
            self.complain('expired', now_s, f'no fresh command for '
                          f'{self.loop.timeout_s:g} s: 0 V')
        self.driving = driving
        self.tables.publish(encode_reading(reading), truth, time_us)
        if self.observer is not None:
            self.observer(reading, truth)

    def run(self, stop: threading.Event) -> None:
        """Tick at the loop's instants (phase + k·period on the NT server clock) until
        ``stop`` is set; a late loop runs late, once, and the next keeps the phase."""
        period_s = 1.0 / self.robot.loop_rate_hz
        next_s = loop_instants(self.phase_s, period_s, now_us() * 1e-6)
        while not stop.is_set():
            stop.wait(max(0.0, next_s - now_us() * 1e-6))
            if stop.is_set():
                break
            self.tick(now_us())
            next_s = loop_instants(self.phase_s, period_s, max(next_s, now_us() * 1e-6))

    def close(self) -> None:
        self.tables.close()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='frc_robot_sim', description=__doc__.split('\n')[0])
    parser.add_argument('--port', type=int, help='NT4 port on 127.0.0.1 (default: the '
                        "parameter file's frc_robot_sim nt_port)")
    parser.add_argument('--phase-s', type=float, help='the phase of the loop instants on the '
                        "NT server clock (s, within the period; default: the parameter file's "
                        'frc_robot_sim loop_phase_s)')
    parser.add_argument('--params-file', action='append', default=[],
                        help='parameter file layered over the installed config/arm.yaml '
                             '(repeatable)')
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                        format='[%(levelname)s] [%(name)s]: %(message)s')
    try:
        arm, sim = config.load('sim', *args.params_file)
        robot = load_robot_sim(*args.params_file)
        if args.phase_s is not None:
            robot = robot.with_phase(args.phase_s)
        port = robot.nt_port if args.port is None else args.port
        stand_in = RobotStandIn(arm, sim, robot, port)
    except (ParameterError, OSError) as error:
        log.critical(f'cannot start: {error}')
        return 2
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    problem = raise_process(robot.realtime_priority)       # the loop's and ntcore's threads
    if problem:
        log.warning(problem)
    log.info(f'serving NT4 on {LOOPBACK}:{port}; the arm at {list(sim.initial_position)} rad, '
             f"{'enabled' if robot.start_enabled else 'disabled'}, "
             f'{robot.loop_rate_hz:g} Hz loop at phase {robot.loop_phase_s:g} s')
    try:
        stand_in.run(stop)
    finally:
        stand_in.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
