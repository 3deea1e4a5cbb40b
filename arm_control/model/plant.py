"""The simulated arm: true state, commanded voltages in, sensor readings out.

Each physics substep the motor controllers turn the commands into applied voltages within the
electrical limits (``electrical.PowerSupply``: bus sag, current limits, brownout), and RK4
integrates ``ArmDynamics.derivative`` with them held over the substep.
"""

from dataclasses import dataclass
import math

import numpy as np

from arm_control.config import ArmConfig
from arm_control.model.dynamics import ArmDynamics, rk4
from arm_control.model.electrical import PowerState, PowerSupply
from arm_control.model.sensors import Sensors

# A brownout ends when this long has passed with every substep's bus above the threshold.
BROWNOUT_GAP_S = 0.02


@dataclass(frozen=True)
class Reading:
    """One sample of every sensor, plus the truth it was taken from."""

    time_s: float
    potentiometer_rad: np.ndarray
    velocity_rad_s: np.ndarray
    effort_nm: np.ndarray            # motor torque at each joint, as the motor controller reports
    encoder_rad: np.ndarray          # relative to the last zeroing, through the lash
    encoder_velocity_rad_s: np.ndarray
    true_state: np.ndarray           # [θa, θb, ωa, ωb]
    voltage: np.ndarray              # applied by the motor controllers
    bus_voltage: float
    motor_current_a: np.ndarray      # stator current of one motor of each joint
    supply_current_a: float          # drawn from the battery (negative: charging it)


@dataclass(frozen=True)
class Brownout:
    """A stretch during which the bus fell below the brownout voltage: outputs at 0 V."""

    start_s: float
    end_s: float
    disabled_s: float                # of which substeps actually browned out

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s


class ArmPlant:
    """Integrates the arm with RK4 on fixed substeps, with hard stops and the electrical
    limits. ``set_voltage`` is the command; what the motors get is ``power.applied_v``."""

    def __init__(self, arm: ArmConfig, initial_position, physics_step_s: float = 0.001,
                 seed: int | None = 0):
        self.arm = arm
        self.dynamics = ArmDynamics(arm)
        self.supply = PowerSupply(arm, self.dynamics.motors)
        self.physics_step_s = physics_step_s
        self.limits = [(j.min_angle_rad, j.max_angle_rad) for j in arm.joints]
        self.sensors = Sensors(arm.joints, initial_position, np.random.default_rng(seed))
        self.command = (0.0, 0.0)
        self.power: PowerState = self.supply.solve(self.command, (0.0, 0.0))
        self.time_s = 0.0
        self.resting = False
        self._brownout: list | None = None      # [start, last browned-out substep, disabled]
        self.brownouts: list[Brownout] = []     # finished ones, for whoever reports them
        self.reset(initial_position)

    def reset(self, position, velocity=(0.0, 0.0)) -> None:
        """Put the arm at ``position`` moving at ``velocity``; the encoders restart from zero."""
        clamped = [min(max(p, lo), hi) for p, (lo, hi) in zip(position, self.limits)]
        self.state = [float(clamped[0]), float(clamped[1]), float(velocity[0]), float(velocity[1])]
        self.sensors.zero(clamped)
        self._last_encoder = self.sensors.encoders()
        self._last_encoder_time_s = self.time_s

    def set_voltage(self, voltage) -> None:
        """Command ``voltage`` from now on, clamped to ±nominal battery volts; NaN is refused."""
        if len(voltage) != 2 or not all(math.isfinite(v) for v in voltage):
            raise ValueError(f'voltage must be two finite numbers, got {list(voltage)}')
        limit = self.arm.battery.nominal_voltage
        self.command = tuple(min(max(float(v), -limit), limit) for v in voltage)

    @property
    def voltage(self) -> tuple[float, float]:
        """The voltage the motors get now."""
        return self.power.applied_v

    def rest(self) -> None:
        """Hold the arm still where it is, as on its stow support, until ``release``."""
        self.resting = True
        self.state[2:] = [0.0, 0.0]

    def release(self) -> None:
        self.resting = False

    def advance(self, duration_s: float) -> None:
        """Step the physics forward by ``duration_s`` (rounded to whole substeps)."""
        steps = max(0, round(duration_s / self.physics_step_s))
        if self.resting:
            self.time_s += steps * self.physics_step_s
            return
        for _ in range(steps):
            self.power = self.supply.solve(self.command, self.state[2:])
            self._follow_brownout(self.power.browned_out)
            self.state = rk4(self.dynamics.derivative, self.state, self.power.applied_v,
                             self.physics_step_s)
            self._hard_stops()
            self.sensors.follow(self.state[:2])
            self.time_s += self.physics_step_s

    def _follow_brownout(self, browned_out: bool) -> None:
        now, step = self.time_s, self.physics_step_s
        if browned_out:
            if self._brownout is None:
                self._brownout = [now, now, 0.0]
            self._brownout[1] = now
            self._brownout[2] += step
        elif self._brownout is not None and now - self._brownout[1] >= BROWNOUT_GAP_S:
            start, last, disabled = self._brownout
            self.brownouts.append(Brownout(start, last + step, disabled))
            self._brownout = None

    @property
    def browned_out_since_s(self) -> float | None:
        """When the brownout going on now began (None when there is none)."""
        return None if self._brownout is None else self._brownout[0]

    def _hard_stops(self) -> None:
        """A joint at a stop stays there; motion into the stop is absorbed (inelastic)."""
        for i, (lo, hi) in enumerate(self.limits):
            if self.state[i] < lo:
                self.state[i] = lo
                self.state[i + 2] = max(0.0, self.state[i + 2])
            elif self.state[i] > hi:
                self.state[i] = hi
                self.state[i + 2] = min(0.0, self.state[i + 2])

    def _power_now(self) -> PowerState:
        return self.power if not self.resting else self.supply.solve((0.0, 0.0), (0.0, 0.0))

    def effort_nm(self) -> np.ndarray:
        """Motor torque at each joint now, as the motor controller reports."""
        return np.array(self.dynamics.motor_torque(self.state[2:], self._power_now().applied_v))

    def read(self) -> Reading:
        position, velocity = self.state[:2], self.state[2:]
        potentiometer, noisy_velocity = self.sensors.potentiometers(position, velocity)
        encoder = self.sensors.encoders()
        elapsed = self.time_s - self._last_encoder_time_s
        encoder_velocity = ((encoder - self._last_encoder) / elapsed if elapsed > 0.0
                            else np.zeros(2))
        self._last_encoder, self._last_encoder_time_s = encoder, self.time_s
        power = self._power_now()
        return Reading(
            time_s=self.time_s,
            potentiometer_rad=potentiometer,
            velocity_rad_s=noisy_velocity,
            effort_nm=self.effort_nm(),
            encoder_rad=encoder,
            encoder_velocity_rad_s=encoder_velocity,
            true_state=np.array(self.state),
            voltage=np.array(power.applied_v),
            bus_voltage=power.bus_voltage,
            motor_current_a=np.array(power.motor_current_a),
            supply_current_a=power.supply_current_a,
        )
