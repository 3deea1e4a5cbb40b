"""The arm description and each node's settings: frozen, validated, read once.

Parameters arrive as a flat mapping of dotted names to values (``arm_control.parameters``),
what a ROS parameter file holds and what a node's declared parameters give back. They are
validated here, so a bad value fails at start with a message naming the parameter and its
value. ``config/arm.yaml`` is the one source of every default.

The arm in ``config.arm``, the nodes' settings in ``config.nodes``; both are read from here.
"""

from arm_control.config.arm import (ArmConfig, BatteryConfig, FRAME_ID, JOINT_NAMES,
                                    JointConfig, MotorDatasheet, Rectangle, WorldConfig,
                                    wpilib_motors)
from arm_control.config.nodes import (COMMAND_MODES, COMMAND_TIMINGS, ControllerConfig, load,
                                      NODE_CONFIGS, PlannerConfig, RecorderConfig, SimConfig)

__all__ = ['ArmConfig', 'BatteryConfig', 'COMMAND_MODES', 'COMMAND_TIMINGS', 'ControllerConfig',
           'FRAME_ID', 'JOINT_NAMES', 'JointConfig', 'load', 'MotorDatasheet', 'NODE_CONFIGS',
           'PlannerConfig', 'Rectangle', 'RecorderConfig', 'SimConfig', 'WorldConfig',
           'wpilib_motors']
