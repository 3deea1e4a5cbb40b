"""A roboRIO's loop over the simulated arm, as the contract tells a robot to run it.

At each loop instant t_k (NT server clock, seconds):

1. the arm has run from t_{k-1} to t_k under the voltage set at t_{k-1} (0 V from its
   command's expiry on, if that came first);
2. the sensors are read: one reading, stamped t_k;
3. the commands that have *arrived* by t_k are taken, newest last (one not newer than the
   command held, or already past its expiry, is refused);
4. the voltage from t_k on: a voltage pair as it is; a profile played at t_k on the fresh
   reading by ``model.profile.ProfilePlayer`` (its setpoint for t_k,
   V = V_ff + kp·(θ_sp − θ) + kd·(θ̇_sp − θ̇)); 0 V while disabled or once the newest
   command has expired: a pair at ``time_us + command_timeout_s``, a profile at its last
   setpoint's instant + ``command_timeout_s`` (played to its end, its last setpoint held).

So a command acts from the first loop after it arrived, never before, and never past its
expiry. No ntcore here: ``robot_sim`` feeds it what NT delivered.
"""

import math

from arm_control.frc.codec import ProfileCommand, Reading, VoltageCommand
from arm_control.frc.conversions import clamp_voltage
from arm_control.frc.rules import ZERO_V
from arm_control.model.profile import ProfilePlayer


class RobotLoop:
    """The loop of steps 1-4 over ``plant`` (an ``ArmPlant``)."""

    def __init__(self, plant, max_voltage: float, command_timeout_s: float):
        if not command_timeout_s > 0.0:
            raise ValueError(f'command timeout must be > 0 s, got {command_timeout_s}')
        self.plant = plant
        self.player = ProfilePlayer(max_voltage)
        self.max_voltage = max_voltage
        self.timeout_s = command_timeout_s
        self.command = None                     # the command held, or None
        self.voltage = ZERO_V                   # set at the last loop ...
        self.voltage_until_s = math.inf         # ... until its command's expiry
        self.last_s = None
        self.refused = []                       # (loop time, command, why) since last asked

    def expires_s(self, command) -> float:
        last_us = command.end_us if isinstance(command, ProfileCommand) else command.time_us
        return last_us * 1e-6 + self.timeout_s

    def take(self, now_s: float, arrived) -> None:
        """Step 3: hold the newest of ``arrived`` (commands, oldest first) if it is newer
        than the one held and not expired."""
        for command in arrived:
            if self.command is not None and command.time_us <= self.command.time_us:
                self.refused.append((now_s, command, 'not newer'))
            elif now_s >= self.expires_s(command):
                self.refused.append((now_s, command, 'stale'))
            else:
                if isinstance(command, ProfileCommand):
                    if not isinstance(self.command, ProfileCommand):
                        self.player.clear()
                    self.player.offer(command.profile)
                else:
                    self.player.clear()
                self.command = command

    def step(self, now_s: float, enabled: bool, arrived=()):
        """One loop at ``now_s``: returns (the reading, the plant's true state at now_s)."""
        if self.last_s is not None and now_s > self.last_s:
            driven_s = min(now_s, max(self.voltage_until_s, self.last_s)) - self.last_s
            if driven_s > 0.0:
                self.plant.advance(driven_s)
            if driven_s < now_s - self.last_s:
                self.plant.set_voltage(ZERO_V)
                self.plant.advance(now_s - self.last_s - driven_s)
        self.last_s = now_s
        sensed = self.plant.read()
        position = tuple(float(q) for q in sensed.potentiometer_rad)
        velocity = tuple(float(v) for v in sensed.velocity_rad_s)
        if enabled:
            self.take(now_s, arrived)
        else:
            self.command = None
            self.player.clear()
        command, voltage = self.command, None
        if command is not None and now_s < self.expires_s(command):
            voltage = command.voltage_v if isinstance(command, VoltageCommand) else \
                self.player.volts(now_s, position, velocity)
        if voltage is None:
            self.voltage, self.voltage_until_s = ZERO_V, math.inf
        else:
            self.voltage = clamp_voltage(voltage, self.max_voltage)
            self.voltage_until_s = self.expires_s(command)
        if self.plant.resting and any(v != 0.0 for v in self.voltage):
            self.plant.release()
        self.plant.set_voltage(self.voltage)
        reading = Reading(
            time_us=round(now_s * 1e6), enabled=enabled, position_rad=position,
            velocity_rad_s=velocity, encoder_rad=tuple(float(q) for q in sensed.encoder_rad),
            motor_current_a=tuple(float(i) for i in sensed.motor_current_a),
            bus_voltage_v=float(sensed.bus_voltage),
            supply_current_a=float(sensed.supply_current_a), applied_voltage_v=self.voltage)
        return reading, tuple(float(x) for x in sensed.true_state)


def loop_instants(phase_s: float, period_s: float, after_s: float) -> float:
    """The first loop instant after ``after_s``: t = phase + k·period."""
    k = math.floor((after_s - phase_s) / period_s) + 1
    return phase_s + k * period_s
