"""The controller's settings, checked whole: the same checks at start and for every change
at run time, so that a change is taken whole or refused with the reason, and nothing the
control loop builds from it can fail after it was taken.

Checked: each value (``config``), the reserves against the battery (``check_against``), the
trajectory limits they leave above the back-EMF (``TrajectoryLimits``), what the motors
surely give for braking and holds (``sure_limits``: positive and finite), the gains against
what the loop holds at its rate and delay (``gain_limits``), and the presets' moves.
"""

from dataclasses import dataclass, replace
import math
from typing import Any, Mapping

import numpy as np

from arm_control.config import ArmConfig, ControllerConfig
from arm_control.control.gain_limits import check_gains
from arm_control.control.safety import sure_limits
from arm_control.model.kinematics import UnreachableError
from arm_control.parameters import ParameterError
from arm_control.plans.cache import preset_pairs
from arm_control.plans.goals import GoalValidator
from arm_control.plans.timer import PlanTimer

# The controller's settings that may change while it runs (a name, or a prefix ending in
# '.'): gains, integrator limit, reserves, tolerances, dwell and presets.
TUNABLE = ('shoulder_pid', 'elbow_pid', 'integrator_limit_v', 'feedback_voltage_reserve',
           'driving_voltage_reserve', 'goal_tolerance_rad', 'settled_velocity_rad_s',
           'dwell_s', 'presets.')


@dataclass(frozen=True)
class ControllerSettings:
    """Checked settings, with what the core builds from them (so a retune only assigns)."""

    arm: ArmConfig
    config: ControllerConfig
    plan_timer: PlanTimer
    max_velocity_rad_s: np.ndarray
    max_acceleration_rad_s2: np.ndarray


def controller_settings(params: Mapping[str, Any], previous=None) -> ControllerSettings:
    """The controller's settings from its parameters, or ``ParameterError`` naming the one
    that cannot be taken and why. ``previous``: the settings in force, whose sure limits
    are kept when nothing they depend on changed (finding them takes a tenth of a second
    of the executor, whose readings the loop then lacks)."""
    arm = ArmConfig.from_parameters(params)
    config = ControllerConfig.from_parameters(params)
    config.check_against(arm)
    timer = PlanTimer(arm, config)
    if previous is not None and _limits_inputs(previous.arm, previous.config) == \
            _limits_inputs(arm, config):
        speed, acceleration = previous.max_velocity_rad_s, previous.max_acceleration_rad_s2
    else:
        speed, acceleration = sure_limits(timer.dynamics, timer.forbidden, arm, config)
    for name, values in (('max_velocity_rad_s', speed), ('max_acceleration_rad_s2',
                                                         acceleration)):
        if not all(math.isfinite(v) and v > 0.0 for v in values):
            raise ParameterError(
                f"parameter 'feedback_voltage_reserve' = {config.feedback_voltage_reserve}, "
                f"'driving_voltage_reserve' = {config.driving_voltage_reserve}: leave the "
                f'motors no sure {name.split("_")[1]} in some pose '
                f'({[round(float(v), 3) for v in values]}), so the '
                'arm could be neither braked nor held')
    check_gains(arm, config)
    validator = GoalValidator(arm)
    for name, x_m, y_m in arm.presets:
        try:
            validator.free_configurations(x_m, y_m)
        except UnreachableError as error:
            raise ParameterError(f"parameter 'presets.{name}' = {[x_m, y_m]}: {error}") from None
    preset_pairs(validator)
    return ControllerSettings(arm, config, timer, speed, acceleration)


def _limits_inputs(arm: ArmConfig, config: ControllerConfig) -> tuple:
    """What ``sure_limits`` depends on: the arm but its presets, the reserves and caps."""
    return (replace(arm, presets=()), config.driving_voltage_reserve,
            config.feedback_voltage_reserve, config.max_velocity_rad_s,
            config.max_acceleration_rad_s2)


def changed_names(old: ControllerSettings, new: ControllerSettings) -> list:
    """The tunable settings whose values differ (``presets`` for any preset)."""
    names = [name for name in TUNABLE if getattr(new.config, name, None) !=
             getattr(old.config, name, None)]
    return names + (['presets'] if new.arm.presets != old.arm.presets else [])
