"""The NetworkTables 4 contract between the robot (the roboRIO, NT server) and the bridge.

Every NT topic either side uses is named here once, with its type, unit, rate and who
publishes it; ``docs/frc_bridge.md`` shows this table (a test keeps the two the same).
Arrays of two are always [shoulder, elbow], with the joint conventions of the ROS side:
shoulder from +x counter-clockwise, elbow relative to the upper arm, radians.

Time: every NT4 value carries the time it was set, on the NT server's clock (ntcore
converts to and from each client's own clock). The robot judges a command's age by that
time, so a command held up on its way is refused, not applied late.
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


def _robot(name, type_, unit, meaning, rate='every robot loop (50 Hz)'):
    return NtTopic(f'/arm/robot/{name}', type_, unit, 'robot', rate, meaning)


def _bridge(name, type_, unit, meaning, rate='each controller period (50 Hz)'):
    return NtTopic(f'/arm/command/{name}', type_, unit, 'bridge', rate, meaning)


# Robot -> bridge: what the roboRIO reads and does.
POSITION = _robot('position_rad', 'double[]', 'rad',
                  'joint angles from the absolute sensors (potentiometers, absolute encoders)')
VELOCITY = _robot('velocity_rad_s', 'double[]', 'rad/s', 'joint velocities')
ENCODER = _robot('encoder_rad', 'double[]', 'rad',
                 "the motors' integrated encoders as joint angles through the gearbox "
                 '(relative: zero where they started)')
BUS_VOLTAGE = _robot('bus_voltage_v', 'double', 'V', 'battery (bus) voltage')
SUPPLY_CURRENT = _robot('supply_current_a', 'double', 'A',
                        'current drawn from the battery by the arm, positive while discharging '
                        '(as the PDH reports it)')
MOTOR_CURRENT = _robot('motor_current_a', 'double[]', 'A',
                       'stator current of one motor of each joint')
ENABLED = _robot('enabled', 'boolean', '', 'the Driver Station has the robot enabled')
APPLIED_VOLTAGE = _robot('applied_voltage_v', 'double[]', 'V',
                         "the voltage the robot applied over the loop that ends at the value's "
                         'time: 0 while disabled or when no fresh command', 'every robot loop '
                         '(50 Hz), and at the moment a command expires')

# Bridge -> robot: commands. The robot applies the newest fresh one of either kind.
VOLTAGE_COMMAND = _bridge('voltage_v', 'double[]', 'V',
                          'mode voltage: motor voltages to apply, clamped to the battery; '
                          'also 0 V in either mode when the controller commands nothing')
SETPOINT_POSITION = _bridge('setpoint_rad', 'double[]', 'rad',
                            "mode setpoint: the trajectory's position, for a loop on the "
                            'roboRIO')
SETPOINT_VELOCITY = _bridge('setpoint_velocity_rad_s', 'double[]', 'rad/s',
                            "mode setpoint: the trajectory's velocity")
FEEDFORWARD = _bridge('feedforward_v', 'double[]', 'V',
                      "mode setpoint: the model's voltage for the setpoint's motion; the robot "
                      'adds its feedback')
ARM_STATE = NtTopic('/arm/coprocessor/state', 'string', '', 'bridge', 'on change',
                    "the controller's state (arm_state): for dashboards, LEDs, autonomous")

# The Mechanism2d, where Glass, Shuffleboard and AdvantageScope find it (SmartDashboard.putData).
MECHANISM_TABLE = '/SmartDashboard/Arm'
MECHANISM = NtTopic(MECHANISM_TABLE, 'Mechanism2d', 'm, deg', 'bridge',
                    'each robot reading and setpoint',
                    'the arm as read (orange) and its setpoint ghost (blue)')

# The stand-in's own topics: what a simulator can tell and a Driver Station would do.
TRUE_STATE = NtTopic('/arm/sim/true_state', 'double[]', 'rad, rad/s', 'frc_robot_sim',
                     'every robot loop (50 Hz)',
                     '[shoulder, elbow, shoulder velocity, elbow velocity]: the truth, for '
                     'tests and benchmarks only')
SIM_ENABLE = NtTopic('/arm/sim/enable', 'boolean', '', 'anyone', 'when it changes',
                     'enable (true) or disable the stand-in, as the Driver Station would')

ROBOT_READINGS = (POSITION, VELOCITY, ENCODER, BUS_VOLTAGE, SUPPLY_CURRENT, MOTOR_CURRENT,
                  ENABLED, APPLIED_VOLTAGE)
SETPOINT_COMMAND = (SETPOINT_POSITION, SETPOINT_VELOCITY, FEEDFORWARD)
COMMANDS = (VOLTAGE_COMMAND, *SETPOINT_COMMAND, ARM_STATE)
TOPICS = ROBOT_READINGS + COMMANDS + (MECHANISM, TRUE_STATE, SIM_ENABLE)


def markdown_table() -> str:
    """The contract as the Markdown table in docs/frc_bridge.md."""
    lines = ['| topic | type | unit | published by | rate | meaning |',
             '|---|---|---|---|---|---|']
    for topic in TOPICS:
        lines.append(f'| `{topic.name}` | {topic.type} | {topic.unit or "-"} | '
                     f'{topic.publisher} | {topic.rate} | {topic.meaning} |')
    return '\n'.join(lines)
