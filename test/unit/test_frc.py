"""The FRC bridge's rules and conversions, without ROS: known answers and physical truths."""

import ast
import json
import math
from pathlib import Path
import re
import shutil
import subprocess
import time

import ntcore
import numpy as np
import pytest
from wpilog_reader import read_wpilog

from arm_control.frc import contract, conversions, mechanism, rules, settings as frc_settings
from arm_control.frc.tables import free_port, LOOPBACK
from arm_control.frc.wpilog import RunLog
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.model.plant import ArmPlant
from arm_control.parameters import ParameterError, read_parameter_file

ROOT = Path(__file__).resolve().parents[2]


# ---------------------------------------------------------------------- the contract


def test_the_documented_contract_is_the_code_s():
    doc = (ROOT / 'docs' / 'frc_bridge.md').read_text()
    assert contract.markdown_table() in doc, 'docs/frc_bridge.md: paste contract.markdown_table()'
    assert contract.layout_tables() in doc, 'docs/frc_bridge.md: paste contract.layout_tables()'


def test_the_layouts_tile_their_arrays():
    """Every index of a reading is one field's; a profile point is 6 values after a head of 2."""
    covered = [i for field in contract.READING_LAYOUT
               for i in range(field.start, field.start + field.size)]
    assert covered == list(range(contract.READING_SIZE))
    assert sum(f.size for f in contract.VOLTAGE_LAYOUT) == contract.VOLTAGE_SIZE
    assert sum(f.size for f in contract.PROFILE_HEAD) == contract.PROFILE_HEAD_SIZE
    assert sum(f.size for f in contract.PROFILE_POINT) == contract.PROFILE_POINT_SIZE
    assert contract.READING_LAYOUT[0].name == contract.VOLTAGE_LAYOUT[0].name == 'time_us'


ROBOT_SIDE_TOPICS = [contract.READING, contract.COMMAND]


def test_the_python_robot_example_parses_and_speaks_the_contract():
    """docs/frc_robot/robot.py: valid Python, every NT topic it names is the contract's with
    the contract's type, and its sizes are the layouts'."""
    example = (ROOT / 'docs' / 'frc_robot' / 'robot.py').read_text()
    tree = ast.parse(example)
    named = dict((name, kind) for kind, name in
                 re.findall(r"get(\w+?)Topic\('(/arm/[\w/]+)'\)", example))
    kinds = {'DoubleArray': 'double[]', 'String': 'string', 'Boolean': 'boolean'}
    contract_types = {t.name: t.type for t in contract.TOPICS}
    assert {t.name for t in ROBOT_SIDE_TOPICS} <= set(named)
    assert all(contract_types.get(name) == kinds[kind] for name, kind in named.items())
    constants = {node.targets[0].id: ast.literal_eval(node.value) for node in tree.body
                 if isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name)
                 and isinstance(node.value, ast.Constant)}
    assert constants['READING_SIZE'] == contract.READING_SIZE
    assert constants['VOLTAGE_SIZE'] == contract.VOLTAGE_SIZE
    assert '_now' not in example, 'public API only'


def test_the_java_robot_example_names_every_topic_the_robot_uses():
    """docs/frc_robot/Robot.java (not compiled here): it names the robot's topics, fills the
    reading in the layout's order and size, and uses the layouts' sizes."""
    example = (ROOT / 'docs' / 'frc_robot' / 'Robot.java').read_text()
    for topic in ROBOT_SIDE_TOPICS:
        assert f'getDoubleArrayTopic("{topic.name}")' in example, topic.name
    filled = example.split('readingPub.set(new double[] {')[1].split('}')[0]
    assert len([v for v in filled.split(',') if v.strip()]) == contract.READING_SIZE
    assert f'VOLTAGE_SIZE = {contract.VOLTAGE_SIZE};' in example
    assert f'PROFILE_HEAD = {contract.PROFILE_HEAD_SIZE}, PROFILE_POINT = ' \
        f'{contract.PROFILE_POINT_SIZE};' in example
    assert 'nt.flush();' in example and 'getFPGATime()' in example


@pytest.mark.skipif(shutil.which('javac') is None, reason='no javac here')
def test_the_java_robot_example_is_java(tmp_path):
    """javac parses docs/frc_robot/Robot.java (its syntax only: WPILib is not here to
    compile it against)."""
    parse_only = ['-XDshould-stop.ifError=PARSE', '-XDshould-stop.ifNoError=PARSE']
    result = subprocess.run(['javac', '-d', str(tmp_path), *parse_only,
                             str(ROOT / 'docs' / 'frc_robot' / 'Robot.java')],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr


def test_each_topic_once_and_each_side_in_its_own_table():
    names = [topic.name for topic in contract.TOPICS]
    assert len(names) == len(set(names))
    assert all(t.name.startswith('/arm/robot/') and t.publisher == 'robot'
               for t in contract.ROBOT_READINGS)
    assert all(t.publisher == 'bridge' for t in contract.COMMANDS)


# ---------------------------------------------------------------------- conversions


@pytest.mark.parametrize('values', [[1.0], [1.0, 2.0, 3.0], [math.nan, 0.0], [0.0, math.inf],
                                    ['a', 1.0], []])
def test_a_malformed_pair_is_refused_naming_the_topic(values):
    with pytest.raises(ValueError, match='/arm/robot/position_rad'):
        conversions.joint_pair(values, '/arm/robot/position_rad')


def test_stall_current_gives_stall_torque_through_the_gearbox(arm):
    """τ = n·G·Kt·I: one CIM at its stall current makes its stall torque; the shoulder has
    two of them behind 159.3:1."""
    dynamics = ArmDynamics(arm)
    stall_a = arm.shoulder.motor.stall_current_a
    effort = conversions.joint_effort_nm((stall_a, -stall_a), dynamics)
    assert effort[0] == pytest.approx(2 * 159.3 * arm.shoulder.motor.stall_torque_nm)
    assert effort[1] == pytest.approx(-1 * 159.3 * arm.shoulder.motor.stall_torque_nm)


def test_effort_from_current_is_the_torque_the_sim_reports(arm):
    """The robot reports a motor's current; the bridge's effort must be the torque the sim
    itself reports for the same voltage and speed."""
    plant = ArmPlant(arm, (0.7, -0.4))
    plant.reset((0.7, -0.4), (1.3, -2.1))
    plant.set_voltage((7.5, -4.0))
    plant.advance(0.001)
    reading = plant.read()
    motors = plant.dynamics.motors
    one_motor_a = [m.current_a(v, w)
                   for m, v, w in zip(motors, reading.voltage, reading.true_state[2:])]
    assert conversions.joint_effort_nm(one_motor_a, plant.dynamics) == \
        pytest.approx(tuple(reading.effort_nm))


def test_battery_current_is_negative_while_discharging():
    assert conversions.battery_state_current_a(42.0) == -42.0


def test_an_nt_value_keeps_its_age_on_the_ros_clock():
    """A value set 20 ms ago on NT's clock is stamped 20 ms before ROS's now."""
    ros_now_ns = 1_700_000_000_123_456_789
    stamp = conversions.ros_stamp_ns(value_time_us=5_000_000, nt_now_us=5_020_000,
                                     ros_now_ns=ros_now_ns)
    assert ros_now_ns - stamp == 20_000_000


def test_only_exactly_zero_means_not_commanding():
    assert not conversions.commanding((0.0, 0.0))
    assert not conversions.commanding((0.0, -0.0))
    assert conversions.commanding((0.0, 1e-9))


@pytest.mark.parametrize('position', [(0.3, 0.5), (1.5708, -1.5708), (2.4, 1.1)])
def test_feedforward_of_a_still_setpoint_holds_the_arm(arm, position):
    """Held at a still setpoint, the model's voltage keeps the arm there: the sim, given it
    open loop, drifts less than 0.5° in 2 s."""
    feedforward = conversions.SetpointFeedforward(ArmDynamics(arm), arm.battery.nominal_voltage)
    for k in range(3):
        voltage = feedforward(0.02 * k, position, (0.0, 0.0))
    plant = ArmPlant(arm, position)
    plant.set_voltage(voltage)
    plant.advance(2.0)
    assert np.max(np.abs(np.array(plant.state[:2]) - position)) < math.radians(0.5)


def test_feedforward_gives_the_setpoint_s_acceleration(arm):
    """Setpoints of a motion at constant acceleration: the feedforward voltage, through the
    forward dynamics, accelerates the arm as the setpoints do."""
    dynamics = ArmDynamics(arm)
    feedforward = conversions.SetpointFeedforward(dynamics, arm.battery.nominal_voltage)
    acceleration = np.array([3.0, -5.0])
    for k in range(5):
        t = 0.02 * k
        q = np.array([0.5, 0.8]) + 0.5 * acceleration * t ** 2
        qd = acceleration * t
        voltage = feedforward(t, q, qd)
    state = [*q, *qd]
    achieved = np.array(dynamics.derivative(state, voltage)[2:])
    assert achieved == pytest.approx(acceleration, rel=1e-6)


def test_feedforward_takes_no_acceleration_across_a_gap(arm):
    dynamics = ArmDynamics(arm)
    feedforward = conversions.SetpointFeedforward(dynamics, arm.battery.nominal_voltage)
    feedforward(0.0, (0.5, 0.5), (0.0, 0.0))
    after_gap = feedforward(1.0, (0.5, 0.5), (2.0, 0.0))       # 1 s later: not a 2 rad/s² jump
    assert after_gap == pytest.approx(dynamics.voltage_for((0.5, 0.5), (2.0, 0.0), (0.0, 0.0)))


# ---------------------------------------------------------------------- the bridge's link


def test_the_link_goes_found_lost_back_with_one_event_each():
    link = rules.RobotLink(0.1)
    assert link.outgoing((3.0, 4.0)) == rules.ZERO_V              # nothing heard yet
    event = link.on_reading(1.0, robot_enabled=True)
    assert (event.previous, event.state) == (rules.LinkState.CONNECTING, rules.LinkState.ENABLED)
    assert event.controller_enabled is True
    assert link.may_command and link.outgoing((3.0, 4.0)) == (3.0, 4.0)
    assert link.check(1.0, nt_connected=True) is None
    for k in range(1, 5):
        assert link.check(1.0 + 0.02 * k, nt_connected=True) is None   # 0.08 s: not yet
    lost = link.check(1.12, nt_connected=True)
    assert lost.level == 'error' and lost.state == rules.LinkState.LOST and lost.nt_connected
    assert lost.silent_s == pytest.approx(0.12)
    # Lost is not disabled: the controller stops as its joint states stop, and carries on
    # with its goals when they return.
    assert lost.controller_enabled is None
    # Lost, nothing is sent, not even 0 V: a link that only stalled would deliver it late
    # and drop an arm the robot holds where its last profile ends.
    assert not link.may_command and link.outgoing((3.0, 4.0)) is None
    assert link.check(2.0, nt_connected=False) is None            # said once
    back = link.on_reading(2.5, robot_enabled=True)
    assert back.level == 'info'
    assert (back.previous, back.state) == (rules.LinkState.LOST, rules.LinkState.ENABLED)
    assert link.outgoing((3.0, 4.0)) == (3.0, 4.0)


def test_a_disabled_robot_gets_0v_and_a_disabled_controller():
    link = rules.RobotLink(0.1)
    link.on_reading(1.0, robot_enabled=True)
    event = link.on_reading(1.02, robot_enabled=False)
    assert event.level == 'warning' and event.state == rules.LinkState.DISABLED
    assert event.controller_enabled is False
    assert not link.may_command and link.outgoing((5.0, 5.0)) == rules.ZERO_V
    enabled = link.on_reading(1.04, robot_enabled=True)
    assert enabled.state == rules.LinkState.ENABLED and enabled.controller_enabled is True


# ---------------------------------------------------------------------- settings


def bridge_parameters(**changes):
    params = read_parameter_file(ROOT / 'config' / 'arm.yaml', 'frc_bridge')
    params.update(changes)
    return params


@pytest.mark.parametrize('changes, words', [
    (dict(mode='torque'), "'mode' = 'torque'"),
    (dict(team_number=30000), "'team_number' = 30000"),
    (dict(nt_port=0), "'nt_port' = 0"),
    (dict(nt_port=70000), "'nt_port' = 70000"),
    (dict(team_number=0, server_address=''), "'server_address' is empty"),
    (dict(reading_timeout_s=0.0), "'reading_timeout_s' = 0.0"),
])
def test_bad_bridge_settings_are_named(changes, words):
    with pytest.raises(ParameterError, match=words.replace('(', r'\(')):
        frc_settings.FrcBridgeConfig.from_parameters(bridge_parameters(**changes))


def test_a_team_number_is_the_server():
    config = frc_settings.FrcBridgeConfig.from_parameters(bridge_parameters(team_number=6328))
    assert config.server == 'team 6328 (port 5810)'


# ---------------------------------------------------------------------- Mechanism2d


@pytest.fixture
def nt_pair():
    """An NT4 server and a client connected to it, on a free loopback port."""
    server, client = ntcore.NetworkTableInstance.create(), ntcore.NetworkTableInstance.create()
    port = free_port()
    server.startServer('', LOOPBACK, 0, port)
    client.startClient4('test')
    client.setServer(LOOPBACK, port)
    deadline = time.monotonic() + 5.0
    while not client.isConnected() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert client.isConnected()
    yield server, client
    client.stopClient()
    server.stopServer()
    ntcore.NetworkTableInstance.destroy(client)
    ntcore.NetworkTableInstance.destroy(server)


def read_tree(instance, prefix: str, timeout_s=2.0) -> dict:
    """Every topic under ``prefix`` with its value, as a dashboard would see it."""
    subscriber = ntcore.MultiSubscriber(instance, [prefix])
    poller = ntcore.NetworkTableListenerPoller(instance)
    poller.addListener(subscriber, ntcore.EventFlags.kValueAll | ntcore.EventFlags.kImmediate)
    values, deadline = {}, time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for event in poller.readQueue():
            data = event.data
            if hasattr(data, 'value'):
                values[data.topic.getName()] = data.value.value()
        time.sleep(0.05)
    return values


def test_the_mechanism_draws_the_arm_where_it_is(arm, nt_pair):
    """What a dashboard reads back is a Mechanism2d whose ligaments end at the tool: from the
    root, each ligament turned by its angle from its parent's direction."""
    server, client = nt_pair
    drawn = mechanism.Mechanism2dPublisher(server, arm)
    position, setpoint = (0.7, -1.9), (2.2, 0.4)
    drawn.show('arm', position)
    drawn.show('setpoint', setpoint)
    server.flush()
    table = contract.MECHANISM_TABLE
    tree = read_tree(client, table + '/')
    assert tree[f'{table}/.type'] == 'Mechanism2d'
    properties = client.getTopic(f'{table}/.type').getProperties()
    assert properties.get('SmartDashboard') == 'Mechanism2d'
    width, height = tree[f'{table}/dims']
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    for root, q in (('arm', position), ('setpoint', setpoint)):
        x, y = tree[f'{table}/{root}/x'], tree[f'{table}/{root}/y']
        heading = 0.0
        for path in mechanism.ligament_paths(root):
            assert tree[f'{path}/.type'] == 'line'
            heading += math.radians(tree[f'{path}/angle'])
            x += tree[f'{path}/length'] * math.cos(heading)
            y += tree[f'{path}/length'] * math.sin(heading)
        pivot = (tree[f'{table}/{root}/x'], tree[f'{table}/{root}/y'])
        tool = kinematics.forward(q)
        assert (x - pivot[0], y - pivot[1]) == pytest.approx(tool, abs=1e-9)
        assert 0.0 < x < width and 0.0 < y < height
    assert tree[f'{mechanism.ligament_paths("arm")[0]}/color'] != \
        tree[f'{mechanism.ligament_paths("setpoint")[0]}/color']


# ---------------------------------------------------------------------- .wpilog


def test_the_wpilog_reads_back_with_names_units_times_and_values(tmp_path):
    path = tmp_path / 'logs' / 'run.wpilog'
    log = RunLog(path)
    log.append(contract.READING.name, (0.5, -1.25), 1_000_000)
    log.append(contract.READING.name, (0.6, -1.2), 1_020_000)
    log.append(contract.COMMAND.name, (1_020_000, 11.7, 0.0), 1_020_000)
    log.append(contract.ARM_STATE.name, 'tracking', 1_030_000)
    log.close()
    entries = read_wpilog(path)
    kind, metadata, samples = entries[contract.READING.name]
    assert kind == 'double[]' and json.loads(metadata) == {'unit': 'see the layout'}
    assert samples == [(1_000_000, [0.5, -1.25]), (1_020_000, [0.6, -1.2])]
    assert entries[contract.COMMAND.name][2] == [(1_020_000, [1_020_000, 11.7, 0.0])]
    assert entries[contract.ARM_STATE.name][:1] == ('string',)
    assert entries[contract.ARM_STATE.name][2] == [(1_030_000, 'tracking')]


def test_an_existing_log_is_never_overwritten(tmp_path):
    path = tmp_path / 'run.wpilog'
    path.write_bytes(b'an older run')
    log = RunLog(path)
    log.close()
    assert path.read_bytes() == b'an older run'
    assert log.path == tmp_path / 'run_1.wpilog' and log.path.is_file()
