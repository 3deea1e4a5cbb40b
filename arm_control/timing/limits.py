"""What a trajectory may use: the motors' volts within the bus, the motor controllers'
current limits, the battery's sag, speed and acceleration caps, and the reserves kept back
for the feedback.

Each joint's motors may get volts with the joint's motion (driving) up to the bus less the
driving reserve, and against it (braking) up to the bus less the feedback reserve: an arm
ahead of its setpoint needs more braking than planned, while an arm behind catches up by
braking less. The current limit is a window of I_limit·R volts either side of the back-EMF,
|V − e·q̇| ≤ I_limit·R, kept back by the same reserves. The bus sags under the trajectory's
own draw (``model.electrical``); where the current limits alone would let it fall below
the brownout voltage (plus a margin), the motors' currents together are held to what keeps it
there.
"""

from dataclasses import dataclass
import math
from typing import Optional

import numpy as np

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.electrical import PowerSupply
from arm_control.parameters import ParameterError

# The timing keeps the bus this far above the brownout voltage.
BROWNOUT_MARGIN_V = 0.25


class TrajectoryError(ValueError):
    """No trajectory along this path: it leaves free space, or the arm cannot follow it."""


@dataclass(frozen=True)
class TrajectoryLimits:
    """Per-joint speed and acceleration caps (inf: no cap, no row at all), the volts at the
    nominal bus (driving, and braking: None for the same), and the supply: the battery and
    the current limits (None: a stiff supply with no current limits)."""

    max_velocity_rad_s: tuple[float, float]
    max_acceleration_rad_s2: tuple[float, float]
    max_voltage: float          # arm.battery.nominal_voltage − controller.driving_voltage_reserve
    max_braking_voltage: Optional[float] = None   # ... − feedback_voltage_reserve
    supply: Optional[PowerSupply] = None

    @property
    def budget(self) -> tuple[float, float]:
        """(driving, braking) volts at the nominal bus."""
        braking = self.max_voltage if self.max_braking_voltage is None \
            else self.max_braking_voltage
        return (self.max_voltage, braking)

    @property
    def nominal_voltage(self) -> float:
        return self.supply.nominal_voltage if self.supply else max(self.budget)

    @property
    def reserves_v(self) -> np.ndarray:
        """(driving, braking) volts kept back from the bus and from the current windows."""
        return self.nominal_voltage - np.array(self.budget)

    @property
    def current_budget_v(self) -> np.ndarray:
        """(2 joints, (driving, braking)) volts either side of the back-EMF: I_limit·R less
        the reserves; inf without a limit."""
        windows = self.supply.current_window_v if self.supply else (math.inf, math.inf)
        return np.array(windows)[:, None] - self.reserves_v

    @property
    def bus_floor_v(self) -> float:
        """The lowest bus the timing allows: the brownout voltage plus a margin."""
        if self.supply is None:
            return -math.inf
        return self.supply.brownout_voltage + BROWNOUT_MARGIN_V

    def supply_current_a(self) -> float:
        """Σ n·|I| over every motor that keeps the bus above ``bus_floor_v`` whatever the
        volts, or inf when the current limits already do: with |V| ≤ V_bus each motor draws
        at most its stator current from the battery, so V_bus ≥ V_nominal − R_battery·Σ n·|I|.
        """
        supply = self.supply
        if supply is None or supply.resistance_ohm == 0.0 \
                or supply.min_bus_voltage() >= self.bus_floor_v:
            return math.inf
        return (supply.nominal_voltage - self.bus_floor_v) / supply.resistance_ohm

    def lowest_bus_v(self) -> float:
        """The lowest bus a timing within every row can leave (its voltages within it)."""
        if self.supply is None:
            return self.nominal_voltage
        lowest = self.supply.min_bus_voltage()
        return lowest if lowest >= self.bus_floor_v else self.bus_floor_v

    @classmethod
    def from_arm(cls, arm: ArmConfig) -> 'TrajectoryLimits':
        """The arm's own limits: its supply and current limits, no caps, no reserves."""
        volts = arm.battery.nominal_voltage
        return cls((math.inf, math.inf), (math.inf, math.inf), volts, volts,
                   PowerSupply(arm, ArmDynamics(arm).motors))

    @classmethod
    def from_config(cls, arm: ArmConfig, controller: ControllerConfig) -> 'TrajectoryLimits':
        """The controller's caps and reserves on this arm's supply."""
        controller.check_against(arm)
        volts = arm.battery.nominal_voltage
        limits = cls(controller.max_velocity_rad_s, controller.max_acceleration_rad_s2,
                     volts - controller.driving_voltage_reserve,
                     volts - controller.feedback_voltage_reserve,
                     PowerSupply(arm, ArmDynamics(arm).motors))
        for joint, windows in zip(arm.joints, limits.current_budget_v):
            if min(windows) <= 0.0:
                raise ParameterError(
                    f"parameter '{joint.name}.current_limit_a' = {joint.current_limit_a}: "
                    'leaves no volts above the back-EMF once the controller keeps its reserves '
                    f'({controller.driving_voltage_reserve} V driving, '
                    f'{controller.feedback_voltage_reserve} V braking) are kept back')
        return limits


def window(dq, driving, braking):
    """(centre, half-width) of the interval allowed where the path direction is q': [−braking,
    driving] for a joint moving forward (q' > 0), [−driving, braking] backward,
    ±max(driving, braking) where it is still; arrays broadcast."""
    direction = np.sign(dq)
    driving, braking = np.asarray(driving, float), np.asarray(braking, float)
    centre = direction * (driving - braking) / 2.0
    half = np.where(direction == 0.0, np.maximum(driving, braking), (driving + braking) / 2.0)
    return centre, half
