"""The NetworkTables 4 contract between the robot (the roboRIO, NT server) and the bridge.

Every NT topic either side uses is named here once, with its type, unit, rate and who
publishes it, and the two arrays that carry the loop (``READING``, ``COMMAND``) have their
layouts here; ``docs/frc_bridge.md`` shows these tables (a test keeps them the same).
Pairs are always [shoulder, elbow], with the joint conventions of the ROS side: shoulder
from +x counter-clockwise, elbow relative to the upper arm, radians.

Time: every time in the contract is on the NT server's clock (the robot's: its FPGA clock
on a roboRIO), in microseconds. A reading is one value, stamped with the instant its
sensors were read; a command names the instant it is for. The robot judges a command's
age by that instant, so a command held up on its way is refused, not applied late.
"""

from dataclasses import dataclass

LOOP_PERIOD_S = 0.02            # an FRC robot loop: readings and commands at 50 Hz


@dataclass(frozen=True)
class NtTopic:
    """One NetworkTables topic of the contract."""

    name: str           # the full topic name
    type: str           # NT type string: double, double[], boolean, string
    unit: str
    publisher: str      # robot, bridge or frc_robot_sim
    rate: str
    meaning: str


@dataclass(frozen=True)
class Field:
    """A run of ``size`` elements of a double[] layout, from index ``start``."""

    name: str
    start: int
    size: int
    unit: str
    meaning: str

    @property
    def indices(self) -> slice:
        return slice(self.start, self.start + self.size)


def _layout(*fields, start: int = 0) -> tuple[Field, ...]:
    laid = []
    for name, size, unit, meaning in fields:
        laid.append(Field(name, start, size, unit, meaning))
        start += size
    return tuple(laid)


# One robot loop's readings, all taken at one instant, as one double[] (NaN: not measured).
READING_LAYOUT = _layout(
    ('time_us', 1, 'µs', 'when the sensors were read, on the NT server clock (also the '
     "value's NT timestamp)"),
    ('enabled', 1, '-', '1 while the Driver Station has the robot enabled, else 0'),
    ('position_rad', 2, 'rad', 'joint angles from the absolute sensors'),
    ('velocity_rad_s', 2, 'rad/s', 'joint velocities'),
    ('encoder_rad', 2, 'rad', "the motors' integrated encoders as joint angles through the "
     'gearbox (relative: zero where they started); NaN if none'),
    ('motor_current_a', 2, 'A', 'stator current of one motor of each joint; NaN if none'),
    ('bus_voltage_v', 1, 'V', 'battery (bus) voltage'),
    ('supply_current_a', 1, 'A', 'current the arm draws from the battery, positive while '
     'discharging (as the PDH reports it); NaN if none'),
    ('applied_voltage_v', 2, 'V', 'what this loop applies from this instant on: 0 while '
     'disabled or without a fresh command'),
)
READING_SIZE = sum(field.size for field in READING_LAYOUT)
READING_FIELD = {field.name: field for field in READING_LAYOUT}

# A command: a voltage pair, or a profile of setpoints the robot plays at its own loop
# (arm_control.model.profile's layout, its start on the NT server clock in µs).
COMMAND_HEAD = _layout(
    ('time_us', 1, 'µs', 'the instant the command is for (a profile: its setpoint 0), on the '
     'NT server clock'),
)
VOLTAGE_LAYOUT = COMMAND_HEAD + _layout(
    ('voltage_v', 2, 'V', 'motor voltages to apply from time_us on, clamped to the battery, '
     'until time_us + the command timeout'), start=1)
VOLTAGE_SIZE = 3
PROFILE_HEAD = COMMAND_HEAD + _layout(
    ('step_s', 1, 's', 'setpoint k is for time_us + k·step_s (the robot loop period)'),
    ('shoulder_pd', 2, 'V/rad, V·s/rad', 'kp, kd the robot closes the shoulder with'),
    ('elbow_pd', 2, 'V/rad, V·s/rad', 'kp, kd for the elbow'), start=1)
PROFILE_POINT = _layout(
    ('position_rad', 2, 'rad', "setpoint k's position"),
    ('velocity_rad_s', 2, 'rad/s', "setpoint k's velocity"),
    ('feedforward_v', 2, 'V', "the model's voltage for setpoint k's motion; the robot adds "
     'its PD feedback on its fresh reading'),
)
PROFILE_POINT_SIZE = 6
PROFILE_HEAD_SIZE = 6


def _robot(name, type_, unit, meaning, rate='every robot loop (50 Hz)'):
    return NtTopic(f'/arm/robot/{name}', type_, unit, 'robot', rate, meaning)


READING = _robot('reading', 'double[]', 'see the layout',
                 'one loop\'s readings, whole: the "reading" layout, stamped when the sensors '
                 'were read')
COMMAND = NtTopic('/arm/command/motors', 'double[]', 'see the layout', 'bridge',
                  'each controller period (50 Hz), flushed at once',
                  'a voltage pair (3 values) or a profile (6 + 6·n values) for the robot to '
                  'apply at its loop: the "command" layouts')
ARM_STATE = NtTopic('/arm/coprocessor/state', 'string', '', 'bridge', 'on change',
                    "the controller's state (arm_state): for dashboards, LEDs, autonomous")

# The Mechanism2d, where Glass, Shuffleboard and AdvantageScope find it (SmartDashboard.putData).
MECHANISM_TABLE = '/SmartDashboard/Arm'
MECHANISM = NtTopic(MECHANISM_TABLE, 'Mechanism2d', 'm, deg', 'bridge',
                    'at most 25 Hz, on its own connection, never flushed',
                    'the arm as read (orange) and its setpoint ghost (blue)')

# The stand-in's own topics: what a simulator can tell and a Driver Station would do.
TRUE_STATE = NtTopic('/arm/sim/true_state', 'double[]', 'µs, rad, rad/s', 'frc_robot_sim',
                     'every robot loop (50 Hz)',
                     '[time_us, shoulder, elbow, shoulder velocity, elbow velocity]: the '
                     "truth at the reading's instant, for tests and benchmarks only")
SIM_ENABLE = NtTopic('/arm/sim/enable', 'boolean', '', 'anyone', 'when it changes',
                     'enable (true) or disable the stand-in, as the Driver Station would')

ROBOT_READINGS = (READING,)
COMMANDS = (COMMAND, ARM_STATE)
TOPICS = ROBOT_READINGS + COMMANDS + (MECHANISM, TRUE_STATE, SIM_ENABLE)


def markdown_table() -> str:
    """The contract as the Markdown table in docs/frc_bridge.md."""
    lines = ['| topic | type | unit | published by | rate | meaning |',
             '|---|---|---|---|---|---|']
    for topic in TOPICS:
        lines.append(f'| `{topic.name}` | {topic.type} | {topic.unit or "-"} | '
                     f'{topic.publisher} | {topic.rate} | {topic.meaning} |')
    return '\n'.join(lines)


def layout_table(title: str, fields, offset: str = '') -> str:
    """A layout as a Markdown table: index, name, unit, meaning (pairs: [shoulder, elbow])."""
    lines = [f'| {title} index | field | unit | meaning |', '|---|---|---|---|']
    for field in fields:
        index = f'{field.start}' if field.size == 1 else f'{field.start}, {field.start + 1}'
        lines.append(f'| {offset}{index} | `{field.name}` | {field.unit} | {field.meaning} |')
    return '\n'.join(lines)


def layout_tables() -> str:
    """Every layout of the contract, as docs/frc_bridge.md shows them."""
    return '\n\n'.join([
        layout_table('reading', READING_LAYOUT),
        layout_table('voltage command', VOLTAGE_LAYOUT),
        layout_table('profile command', PROFILE_HEAD),
        layout_table('profile setpoint k', PROFILE_POINT, '6 + 6·k + '),
    ])
