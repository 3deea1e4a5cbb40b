"""The roboRIO side of docs/frc_bridge.md, in robotpy: paste and adapt (channels, gear
ratio, sensor offsets, your motor controllers). Public API only. Each loop, in this order:
read the sensors (and the time), take the newest command that has arrived, set the motors,
publish the loop's reading as one value stamped with the sensors' time, flush.
"""

import math

import ntcore
import wpilib

GEAR_RATIO = 159.3                   # motor turns per joint turn
ENCODER_CPR = 2048                   # encoder counts per motor turn
COMMAND_TIMEOUT_US = 100_000         # a command drives until its time_us + this, then 0 V
KP = (90.0, 75.0)                    # profile feedback: V/rad, [shoulder, elbow]
KD = (4.0, 3.0)                      # V s/rad
READING_SIZE = 14                    # the reading layout: see docs/frc_bridge.md
VOLTAGE_SIZE = 3                     # a command: [time_us, V_s, V_e] ...
PROFILE_HEAD, PROFILE_POINT = 2, 6   # ... or [time_us, period_s, (q, qd, ff) per setpoint]


def voltage_for(command, now_us, position, velocity):
    """A held command's voltage at now_us: a pair as it is; a profile's setpoint for now_us
    (the last one past its end) closed by PD on this loop's reading."""
    if len(command) == VOLTAGE_SIZE:
        return [command[1], command[2]]
    points = (len(command) - PROFILE_HEAD) // PROFILE_POINT
    k = math.floor((now_us - command[0]) * 1e-6 / command[1] + 1e-6)
    base = PROFILE_HEAD + PROFILE_POINT * min(max(k, 0), points - 1)
    q_sp, qd_sp, ff = (command[base:base + 2], command[base + 2:base + 4],
                       command[base + 4:base + 6])
    return [ff[j] + KP[j] * (q_sp[j] - position[j]) + KD[j] * (qd_sp[j] - velocity[j])
            for j in range(2)]


def is_command(values):
    return len(values) == VOLTAGE_SIZE or (
        len(values) > PROFILE_HEAD and (len(values) - PROFILE_HEAD) % PROFILE_POINT == 0
        and values[1] > 0.0)


class Robot(wpilib.TimedRobot):
    def robotInit(self):
        nt = ntcore.NetworkTableInstance.getDefault()
        fast = ntcore.PubSubOptions(periodic=0.005, keepDuplicates=True, sendAll=True)
        self.nt = nt
        self.reading_pub = nt.getDoubleArrayTopic('/arm/robot/reading').publish(fast)
        self.command_sub = nt.getDoubleArrayTopic('/arm/command/motors').subscribe([], fast)
        self.state_sub = nt.getStringTopic('/arm/coprocessor/state').subscribe('')
        self.held = None                     # the newest command taken

        self.shoulder_motors = [wpilib.PWMTalonSRX(0), wpilib.PWMTalonSRX(1)]
        self.elbow_motor = wpilib.PWMTalonSRX(2)
        # Absolute angles: 10-turn pots or absolute encoders, zeroed to the arm's convention.
        self.shoulder_pot = wpilib.AnalogPotentiometer(0, 2 * math.pi, -math.pi / 2)
        self.elbow_pot = wpilib.AnalogPotentiometer(1, 2 * math.pi, -math.pi)
        self.encoders = [wpilib.Encoder(0, 1), wpilib.Encoder(2, 3)]
        for encoder in self.encoders:
            encoder.setDistancePerPulse(2 * math.pi / (ENCODER_CPR * GEAR_RATIO))
        self.pdh = wpilib.PowerDistribution()

    def robotPeriodic(self):
        # 1. The sensors, and the instant they were read: on a roboRIO the FPGA clock is
        #    the NT server's clock, the time base of the whole contract.
        now_us = wpilib.RobotController.getFPGATime()
        position = [self.shoulder_pot.get(), self.elbow_pot.get()]
        velocity = [encoder.getRate() for encoder in self.encoders]
        encoder = [encoder.getDistance() for encoder in self.encoders]
        current = [self.pdh.getCurrent(0), self.pdh.getCurrent(2)]     # one motor a joint
        supply = sum(self.pdh.getCurrent(c) for c in (0, 1, 2))
        bus = wpilib.RobotController.getBatteryVoltage()
        enabled = wpilib.DriverStation.isEnabled()

        # 2. The newest command that has arrived: taken if newer than the one held and not
        #    past its expiry; dropped while disabled.
        for value in self.command_sub.readQueue():
            command = list(value.value)
            if enabled and is_command(command) and now_us < command[0] + COMMAND_TIMEOUT_US \
                    and (self.held is None or command[0] > self.held[0]):
                self.held = command
        if not enabled:
            self.held = None

        # 3. The voltage from now on: 0 V once the command held is past its expiry.
        voltage = [0.0, 0.0]
        if self.held is not None and now_us < self.held[0] + COMMAND_TIMEOUT_US:
            voltage = voltage_for(self.held, now_us, position, velocity)
        battery = max(bus, 0.0)
        voltage = [min(max(v, -battery), battery) for v in voltage]
        for motor in self.shoulder_motors:
            motor.setVoltage(voltage[0])
        self.elbow_motor.setVoltage(voltage[1])

        # 4. The loop's reading, whole, stamped with the sensors' instant; sent at once.
        reading = [float(now_us), 1.0 if enabled else 0.0, *position, *velocity, *encoder,
                   *current, bus, supply, *voltage]
        assert len(reading) == READING_SIZE
        self.reading_pub.set(reading, now_us)
        self.nt.flush()
