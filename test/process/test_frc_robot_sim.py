"""frc_robot_sim, the roboRIO's stand-in: its loop driven here, in real time, by a client
that speaks the contract like the bridge; then the installed executable."""

import math
import signal
import subprocess
import threading
import time

import ntcore
import numpy as np
import pytest

from arm_control import config
from arm_control.frc import contract as nt
from arm_control.frc.codec import decode_reading, encode_profile, encode_voltage, profile_command
from arm_control.frc.conversions import SetpointFeedforward
from arm_control.frc.robot_sim import RobotStandIn
from arm_control.frc.settings import load_robot_sim
from arm_control.frc.tables import BridgeTables, free_port, LOOPBACK, now_us, RobotTables
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.profile import Profile, Setpoint

PERIOD_S = nt.LOOP_PERIOD_S
TIMEOUT_S = 0.1


def stand_in(phase_s=0.007):
    arm, sim = config.load('sim')
    return RobotStandIn(arm, sim, load_robot_sim().with_phase(phase_s), free_port())


def connect(robot) -> BridgeTables:
    bridge = BridgeTables(ntcore.NetworkTableInstance.create(), 'test', 0, LOOPBACK, robot.port,
                          drawing=False)
    deadline = time.monotonic() + 5.0
    while not bridge.connected() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert bridge.connected()
    return bridge


@pytest.fixture
def robot():
    """The stand-in (ticked by the test) and a client of it, connected."""
    robot = stand_in()
    robot.bridge = connect(robot)
    yield robot
    robot.bridge.close()
    robot.close()


def loops(robot, seconds, before_each=None):
    """Run the robot loop for ``seconds`` of real time; ``before_each()`` just before each."""
    for _ in range(round(seconds / PERIOD_S)):
        if before_each is not None:
            before_each()
            time.sleep(0.002)           # on its way over loopback
        robot.tick(now_us())
        time.sleep(PERIOD_S)


def readings(robot) -> list:
    """Every reading the client has heard, decoded."""
    time.sleep(0.05)
    return [decode_reading(v.value) for v in robot.bridge.reading.readQueue()]


def send(robot, voltage):
    robot.bridge.send_command(encode_voltage(robot.bridge.server_now_us(), voltage))


def test_the_arm_rests_until_the_first_voltage(robot):
    start = list(robot.plant.state)
    loops(robot, 0.2)
    assert robot.plant.state == start
    loops(robot, 0.2, lambda: send(robot, (0.0, 0.0)))    # 0 V: still resting
    assert robot.plant.state == start
    loops(robot, 0.1, lambda: send(robot, (12.0, 0.0)))
    assert robot.plant.state[2] > 0.1              # the shoulder rises under 12 V


def test_commands_drive_until_their_instant_plus_the_timeout_then_0v(robot):
    sent_us = []

    def send_one():
        sent_us.append(robot.bridge.server_now_us())
        robot.bridge.send_command(encode_voltage(sent_us[-1], (6.0, -3.0)))
    loops(robot, 0.3, send_one)
    assert robot.voltage == (6.0, -3.0)
    readings(robot)                                 # what was heard so far
    loops(robot, 0.3)
    after = readings(robot)
    driven = [r.time_us for r in after if r.applied_voltage_v != (0.0, 0.0)]
    stopped = [r.time_us for r in after if r.applied_voltage_v == (0.0, 0.0)]
    assert stopped and max(driven, default=0) < min(stopped)
    assert max(driven, default=0) < sent_us[-1] + TIMEOUT_S * 1e6
    assert robot.voltage == (0.0, 0.0)


def test_a_command_past_its_expiry_is_refused(robot):
    robot.bridge.send_command(encode_voltage(robot.bridge.server_now_us() - 500_000,
                                             (6.0, 6.0)))
    time.sleep(0.02)
    loops(robot, 0.1)
    assert robot.voltage == (0.0, 0.0) and robot.plant.resting


def test_disabled_means_0v_and_disabled_in_the_next_reading(robot):
    enable = robot.bridge.instance.getBooleanTopic(nt.SIM_ENABLE.name).publish()
    loops(robot, 0.1, lambda: send(robot, (12.0, 0.0)))
    assert robot.voltage == (12.0, 0.0)
    readings(robot)
    enable.set(False)
    robot.bridge.instance.flush()
    time.sleep(0.01)
    loops(robot, 0.2, lambda: send(robot, (12.0, 0.0)))
    after = readings(robot)
    assert not after[0].enabled and all(r.applied_voltage_v == (0.0, 0.0) for r in after)
    enable.set(True)
    loops(robot, 0.1, lambda: send(robot, (5.0, 1.0)))
    assert robot.voltage == (5.0, 1.0)


def test_a_profile_holds_the_arm_on_the_robot_s_loop(robot):
    """The robot closes the loop itself (PD + the model's feedforward) on a one-setpoint
    profile, and the arm, off its support, stays where it is told."""
    feedforward = SetpointFeedforward(ArmDynamics(robot.arm), robot.arm.battery.nominal_voltage)
    hold = tuple(robot.plant.state[:2])

    def send_profile():
        t = robot.bridge.server_now_us()
        setpoint = Setpoint(hold, (0.0, 0.0), feedforward(t * 1e-6, hold, (0.0, 0.0)))
        robot.bridge.send_command(encode_profile(profile_command(t, Profile(
            0.0, PERIOD_S, ((90.0, 4.0), (75.0, 3.0)), (setpoint,)))))
    loops(robot, 1.5, send_profile)
    assert not robot.plant.resting
    assert np.max(np.abs(np.array(robot.plant.state[:2]) - hold)) < math.radians(1.0)


def test_readings_follow_the_contract(robot):
    loops(robot, 0.1)
    reading = readings(robot)[-1]
    assert reading.enabled is True
    assert reading.bus_voltage_v == robot.arm.battery.nominal_voltage
    # At 0 V and at rest on its support, no motor draws current.
    assert reading.motor_current_a == (0.0, 0.0) and reading.supply_current_a == 0.0
    start = np.array(config.load('sim')[1].initial_position)
    assert np.max(np.abs(np.array(reading.position_rad) - start)) < math.radians(1.5)


@pytest.mark.parametrize('phase_s', [0.0, 0.0113])
def test_the_loop_runs_at_its_phase_and_stamps_its_readings_there(phase_s):
    """Run on its own, the loop's instants keep their phase of the NT clock (a late wake-up
    is stamped when it ran), and a command acts from the first loop after it arrived."""
    robot = stand_in(phase_s)
    bridge = connect(robot)
    stop = threading.Event()
    runner = threading.Thread(target=robot.run, args=(stop,))
    runner.start()
    try:
        time.sleep(0.3)
        sent_us = bridge.server_now_us()
        bridge.send_command(encode_voltage(sent_us, (0.5, 0.5)))
        time.sleep(0.3)
    finally:
        stop.set()
        runner.join()
    heard = [decode_reading(v.value) for v in bridge.reading.readQueue()]
    bridge.close()
    robot.close()
    # Wake-ups run late on a loaded machine, but near the phase: a loop at any phase would
    # be late by 10 ms at the median.
    late_us = [(r.time_us - round(phase_s * 1e6)) % 20_000 for r in heard]
    assert len(heard) > 20 and np.median(late_us) < 5_000
    acting = [r.time_us for r in heard if r.applied_voltage_v == (0.5, 0.5)]
    assert acting and min(acting) > sent_us


def test_a_port_in_use_is_refused_naming_it():
    port = free_port()
    first = RobotTables(ntcore.NetworkTableInstance.create(), port)
    try:
        time.sleep(0.2)
        with pytest.raises(OSError, match=f'cannot serve NT4 on 127.0.0.1:{port}'):
            RobotTables(ntcore.NetworkTableInstance.create(), port)
    finally:
        first.close()


def test_the_executable_serves_and_stops_on_ctrl_c():
    from ros_harness import install_prefix
    executable = install_prefix() / 'lib' / 'arm_control' / 'frc_robot_sim'
    port = free_port()
    process = subprocess.Popen([str(executable), '--port', str(port)], stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    client = ntcore.NetworkTableInstance.create()
    try:
        bridge = BridgeTables(client, 'test', 0, LOOPBACK, port, drawing=False)
        deadline = time.monotonic() + 10.0
        while not bridge.reading.readQueue() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert bridge.reading.get(), 'no readings from frc_robot_sim'
        bridge.close()
        client = None
        busy = subprocess.run([str(executable), '--port', str(port)], capture_output=True,
                              text=True, timeout=20)
        assert busy.returncode == 2 and f'cannot serve NT4 on 127.0.0.1:{port}' in busy.stderr
    finally:
        process.send_signal(signal.SIGINT)
        output = process.communicate(timeout=10)[0]
        if client is not None:
            ntcore.NetworkTableInstance.destroy(client)
    assert process.returncode == 0, output
    assert f'serving NT4 on 127.0.0.1:{port}' in output


def test_a_command_is_not_queued_behind_drawing():
    """The bridge's tables with a backlog of drawing set just before a command: the command
    reaches the robot first, flushed, and the drawing follows on its own connection. On one
    connection the command could never come first (it would follow the backlog, in order);
    on two, a loaded machine can run the drawing's periodic flush first: three tries."""
    tries = []
    for _ in range(3):
        arrivals, separate = command_after_drawing()
        assert separate                             # drawing never rides a command's flush
        assert nt.COMMAND.name in arrivals and len(arrivals) > 1, arrivals
        tries.append(arrivals[:5])
        if arrivals[0] == nt.COMMAND.name:
            return
    pytest.fail(f'the drawing came first in every try: {tries}')


def command_after_drawing():
    """Topics as the robot's server heard them after 200 drawing updates and then a command
    (for 1 s), and whether the drawing had a connection of its own."""
    from arm_control.frc.mechanism import Mechanism2dPublisher
    arm = config.load('sim')[0]
    server = RobotTables(ntcore.NetworkTableInstance.create(), free_port())
    tables = BridgeTables(ntcore.NetworkTableInstance.create(), 'test', 0, LOOPBACK,
                          server.port)
    arrivals = []
    poller = ntcore.NetworkTableListenerPoller(server.instance)
    try:
        deadline = time.monotonic() + 5.0
        while not (tables.connected() and tables.drawing.isConnected()) and \
                time.monotonic() < deadline:
            time.sleep(0.01)
        drawing = Mechanism2dPublisher(tables.drawing, arm)
        angle = ntcore.MultiSubscriber(server.instance, [nt.MECHANISM_TABLE + '/'])
        poller.addListener(angle, ntcore.EventFlags.kValueRemote)
        poller.addListener(server.command, ntcore.EventFlags.kValueRemote)
        time.sleep(0.3)                         # the layout has gone
        poller.readQueue()
        for k in range(200):
            drawing.show('arm', (0.001 * k, 0.5))
        tables.send_command(encode_voltage(tables.server_now_us(), (1.0, 2.0)))
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            arrivals += [event.data.topic.getName() for event in poller.readQueue()]
            time.sleep(0.001)
    finally:
        tables.close()
        server.close()
    return arrivals, tables.drawing is not tables.instance
