"""A roboRIO's loop over the simulated arm, as the contract tells a robot to run it.

At each loop instant t_k (NT server clock, seconds):

1. the arm has run from t_{k-1} to t_k under the voltage set at t_{k-1} (0 V from a
   pair's timeout on, if that came first);
2. the sensors are read: one reading, stamped t_k;
3. the commands that have *arrived* by t_k are taken (``model.robot_commands``): the
   latest is in charge. One already stale on arrival is refused: a pair past its
   ``time_us + command_timeout_s``, a profile past its last setpoint + the timeout;
4. the voltage from t_k on: a voltage pair as it is until ``time_us + command_timeout_s``,
   then 0 V; a profile played at t_k on the fresh reading (``ProfilePlayer``:
   V = V_ff + kp·(θ_sp − θ) + kd·(θ̇_sp − θ̇)), past its end its last setpoint held at rest
   with its holding volts; 0 V while disabled.

So a command acts from the first loop after it arrived, never before, and a pair never
past its timeout, however late the loop runs. No ntcore here: ``robot_sim`` feeds it what
NT delivered.
"""

import math

from arm_control.frc.codec import ProfileCommand, Reading
from arm_control.frc.conversions import clamp_voltage
from arm_control.frc.rules import ZERO_V
from arm_control.model.robot_commands import RobotCommands


class RobotLoop:
    """The loop of steps 1-4 over ``plant`` (an ``ArmPlant``)."""

    def __init__(self, plant, max_voltage: float, command_timeout_s: float):
        if not command_timeout_s > 0.0:
            raise ValueError(f'command timeout must be > 0 s, got {command_timeout_s}')
        self.plant = plant
        self.max_voltage = max_voltage
        self.timeout_s = command_timeout_s
        self.commands = RobotCommands(max_voltage, command_timeout_s)
        self.voltage = ZERO_V                   # set at the last loop ...
        self.voltage_until_s = math.inf         # ... until a pair's timeout
        self.last_s = None                      # the last loop (or arrival) instant
        self.plant_s = None                     # the instant the plant has reached
        self.refused = []                       # (loop time, command) refused as stale

    def stale(self, command, now_s: float) -> bool:
        last_us = command.end_us if isinstance(command, ProfileCommand) else command.time_us
        return now_s >= last_us * 1e-6 + self.timeout_s

    def take(self, now_s: float, arrived) -> None:
        """Step 3: ``arrived`` (decoded commands, in arrival order) taken at ``now_s``. A
        pair's timeout runs from its own instant, a profile from its start on."""
        for command in arrived:
            if self.stale(command, now_s):
                self.refused.append((now_s, command))
            elif isinstance(command, ProfileCommand):
                self.commands.arrive(now_s, command.profile)
            else:
                self.commands.arrive(min(now_s, command.time_us * 1e-6), command.voltage_v)
        self.commands.take(now_s)

    def run_to(self, now_s: float) -> None:
        """Step 1: the arm run to ``now_s`` under the voltage set last (0 V past a pair's
        timeout). The plant steps whole substeps: its own time is kept, so that the
        rounding never adds up."""
        if self.last_s is None:
            self.last_s = self.plant_s = now_s
            return
        if now_s <= self.last_s:
            return
        until_s = min(now_s, max(self.voltage_until_s, self.plant_s))
        self.advance_to(until_s)
        if until_s < now_s:
            self.plant.set_voltage(ZERO_V)
            self.advance_to(now_s)
        self.last_s = now_s

    def advance_to(self, t_s: float) -> None:
        step_s = self.plant.physics_step_s
        steps = round((t_s - self.plant_s) / step_s)
        if steps > 0:
            self.plant.advance(steps * step_s)
            self.plant_s += steps * step_s

    def step(self, now_s: float, enabled: bool, arrived=()):
        """One loop at ``now_s``: returns (the reading, the plant's true state at now_s)."""
        self.run_to(now_s)
        sensed = self.plant.read()
        self.apply(now_s, enabled, arrived, sensed)
        position = tuple(float(q) for q in sensed.potentiometer_rad)
        velocity = tuple(float(v) for v in sensed.velocity_rad_s)
        reading = Reading(
            time_us=round(now_s * 1e6), enabled=enabled, position_rad=position,
            velocity_rad_s=velocity, encoder_rad=tuple(float(q) for q in sensed.encoder_rad),
            motor_current_a=tuple(float(i) for i in sensed.motor_current_a),
            bus_voltage_v=float(sensed.bus_voltage),
            supply_current_a=float(sensed.supply_current_a), applied_voltage_v=self.voltage)
        return reading, tuple(float(x) for x in sensed.true_state)

    def apply_on_arrival(self, now_s: float, enabled: bool, arrived) -> None:
        """The reference, not a robot: ``arrived`` applied the moment they arrive (as the
        default ``sim`` does), on the sensors of that moment; no reading is published."""
        self.run_to(now_s)
        self.apply(now_s, enabled, arrived, self.plant.read())

    def apply(self, now_s: float, enabled: bool, arrived, sensed) -> None:
        """Steps 3 and 4 with the sensors ``sensed``: the motors set from ``now_s`` on."""
        position = tuple(float(q) for q in sensed.potentiometer_rad)
        velocity = tuple(float(v) for v in sensed.velocity_rad_s)
        if enabled:
            self.take(now_s, arrived)
            self.voltage = clamp_voltage(self.commands.volts(now_s, position, velocity),
                                         self.max_voltage)
        else:                                   # disabled: 0 V, and every command dropped
            self.commands = RobotCommands(self.max_voltage, self.timeout_s)
            self.voltage = ZERO_V
        self.voltage_until_s = math.inf if self.commands.playing else \
            self.commands.pair_s + self.timeout_s
        if self.plant.resting and any(v != 0.0 for v in self.voltage):
            self.plant.release()
        self.plant.set_voltage(self.voltage)

    @property
    def driving(self) -> bool:
        """A command is in charge (a profile, or a pair not timed out)."""
        return self.commands.playing or self.voltage_until_s > self.last_s


def loop_instants(phase_s: float, period_s: float, after_s: float) -> float:
    """The first loop instant after ``after_s``: t = phase + k·period."""
    k = math.floor((after_s - phase_s) / period_s) + 1
    return phase_s + k * period_s
