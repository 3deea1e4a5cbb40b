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
COMMAND_TIMEOUT_US = 100_000         # a pair drives until its time_us + this, then 0 V
READING_SIZE = 14                    # the reading layout: see docs/frc_bridge.md
VOLTAGE_SIZE = 3                     # a command: [time_us, V_s, V_e] ...
PROFILE_HEAD, PROFILE_POINT = 6, 6   # ... or [time_us, step_s, kp_s, kd_s, kp_e, kd_e,
#                                          then (q_s, q_e, qd_s, qd_e, ff_s, ff_e) per setpoint]


def is_command(c):
    return len(c) == VOLTAGE_SIZE or (len(c) > PROFILE_HEAD and c[1] > 0.0 and
                                      (len(c) - PROFILE_HEAD) % PROFILE_POINT == 0)


def points(c):
    return (len(c) - PROFILE_HEAD) // PROFILE_POINT


def begins_us(c):
    """A pair acts on arrival; a profile from half a step before its setpoint 0."""
    return -math.inf if len(c) == VOLTAGE_SIZE else c[0] - 0.5e6 * c[1]


def stale_us(c):
    """Refused on arrival from then on: a pair's instant, a profile's last setpoint's,
    + the timeout. A pair also stops driving then; a profile never does (held at its end)."""
    last_us = c[0] if len(c) == VOLTAGE_SIZE else c[0] + 1e6 * c[1] * (points(c) - 1)
    return last_us + COMMAND_TIMEOUT_US


def voltage_for(c, now_us, position, velocity):
    """A pair as it is. A profile: setpoint k nearest now, q_sp = q_k + qd_k·(t − t_k) (past
    the last, that one held at rest), V = ff_k + kp·(q_sp − q) + kd·(qd_sp − qd)."""
    if len(c) == VOLTAGE_SIZE:
        return [c[1], c[2]]
    step_s, since_s = c[1], (now_us - c[0]) * 1e-6
    k = min(max(math.floor(since_s / step_s + 0.5), 0), points(c) - 1)
    b = PROFILE_HEAD + PROFILE_POINT * k
    q_sp, qd_sp, ff = c[b:b + 2], c[b + 2:b + 4], c[b + 4:b + 6]
    tau_s = min(max(since_s - k * step_s, -0.5 * step_s), 0.5 * step_s)
    if k == points(c) - 1 and since_s - k * step_s > 0.5 * step_s:
        qd_sp = [0.0, 0.0]
    return [ff[j] + c[2 + 2 * j] * (q_sp[j] + qd_sp[j] * tau_s - position[j])
            + c[3 + 2 * j] * (qd_sp[j] - velocity[j]) for j in range(2)]


class Robot(wpilib.TimedRobot):
    def robotInit(self):
        nt = ntcore.NetworkTableInstance.getDefault()
        fast = ntcore.PubSubOptions(periodic=0.005, keepDuplicates=True, sendAll=True)
        self.nt = nt
        self.reading_pub = nt.getDoubleArrayTopic('/arm/robot/reading').publish(fast)
        self.command_sub = nt.getDoubleArrayTopic('/arm/command/motors').subscribe([], fast)
        self.state_sub = nt.getStringTopic('/arm/coprocessor/state').subscribe('')
        self.held = None                     # the command in charge
        self.pending = []                    # profiles arrived, not begun yet

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

        # 2. The commands that have arrived, in order, unless stale: a pair takes charge at
        #    once; a profile from half a step before its start. Disabled: none.
        for value in self.command_sub.readQueue():
            c = list(value.value)
            if not is_command(c) or now_us >= stale_us(c):
                continue
            if len(c) == VOLTAGE_SIZE:
                self.held, self.pending = c, []
            else:
                self.pending.append(c)
        begun = [i for i, c in enumerate(self.pending) if now_us >= begins_us(c)]
        if begun:
            self.held, self.pending = self.pending[begun[-1]], self.pending[begun[-1] + 1:]
        if not enabled:
            self.held, self.pending = None, []

        # 3. The voltage from now on: a pair until its timeout, then 0 V; a profile played.
        voltage = [0.0, 0.0]
        if self.held is not None and (len(self.held) != VOLTAGE_SIZE or
                                      now_us < stale_us(self.held)):
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
