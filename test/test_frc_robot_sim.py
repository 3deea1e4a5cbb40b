"""frc_robot_sim, the roboRIO's stand-in: its loop driven here, in real time, by a client
that speaks the contract like the bridge; then the installed executable."""

import math
import signal
import subprocess
import time

import ntcore
import numpy as np
import pytest

from arm_control import config
from arm_control.frc import contract as nt
from arm_control.frc.conversions import SetpointFeedforward
from arm_control.frc.robot_sim import RobotStandIn
from arm_control.frc.settings import load_robot_sim
from arm_control.frc.tables import BridgeTables, free_port, LOOPBACK, now_us, RobotTables
from arm_control.model.dynamics import ArmDynamics

PERIOD_S = nt.LOOP_PERIOD_S
TIMEOUT_S = 0.1


@pytest.fixture
def robot():
    """The stand-in (ticked by the test) and a client of it, connected."""
    arm, sim = config.load('sim')
    controller = config.load('controller')[1]
    port = free_port()
    stand_in = RobotStandIn(arm, sim, load_robot_sim(),
                            (controller.shoulder_pid, controller.elbow_pid), port)
    client = ntcore.NetworkTableInstance.create()
    bridge = BridgeTables(client, 'test', 0, LOOPBACK, port)
    deadline = time.monotonic() + 5.0
    while not bridge.connected() and time.monotonic() < deadline:
        stand_in.tick(now_us())
        time.sleep(PERIOD_S)
    assert bridge.connected()
    stand_in.bridge = bridge
    yield stand_in
    bridge.close()
    stand_in.close()


def loops(stand_in, seconds, before_each=None):
    """Run the robot loop for ``seconds`` of real time; ``before_each()`` just before each."""
    for _ in range(round(seconds / PERIOD_S)):
        if before_each is not None:
            before_each()
            time.sleep(0.002)           # on its way over loopback
        stand_in.tick(now_us())
        time.sleep(PERIOD_S)


def applied(stand_in) -> list:
    """(time on NT's clock in s, voltage) of every applied_voltage_v the client has heard."""
    time.sleep(0.05)
    return [(v.time * 1e-6, tuple(v.value))
            for v in stand_in.bridge.readings[nt.APPLIED_VOLTAGE].readQueue()]


def test_the_arm_rests_until_the_first_voltage(robot):
    start = list(robot.plant.state)
    loops(robot, 0.2)
    assert robot.plant.state == start
    loops(robot, 0.2, lambda: robot.bridge.send_voltage((0.0, 0.0)))    # 0 V: still resting
    assert robot.plant.state == start
    loops(robot, 0.1, lambda: robot.bridge.send_voltage((12.0, 0.0)))
    assert robot.plant.state[2] > 0.1              # the shoulder rises under 12 V


def test_commands_drive_until_their_timeout_then_0v(robot):
    sent_s = []

    def send():
        robot.bridge.send_voltage((6.0, -3.0))
        sent_s.append(now_us() * 1e-6)
    loops(robot, 0.3, send)
    assert robot.voltage == (6.0, -3.0)
    applied(robot)                                  # what was heard so far
    loops(robot, 0.3)
    after = applied(robot)
    # Each sample is the voltage over the loop that ends at its time: the last one driven
    # ends (and 0 V begins) at most the timeout after the last command, then 0 V only.
    driven = [t for t, v in after if v != (0.0, 0.0)]
    stopped = [t for t, v in after if v == (0.0, 0.0)]
    assert driven and stopped and max(driven) < min(stopped)
    assert max(driven) <= sent_s[-1] + TIMEOUT_S + 0.003      # sent_s: read just after sending
    assert robot.voltage == (0.0, 0.0)


def test_a_command_older_than_the_timeout_is_refused(robot):
    old_us = now_us() - 500_000
    robot.bridge.voltage.set([6.0, 6.0], old_us)
    robot.bridge.instance.flush()
    time.sleep(0.02)
    loops(robot, 0.1)
    assert robot.voltage == (0.0, 0.0) and robot.plant.resting


def test_disabled_means_0v_and_commands_ignored(robot):
    enable = robot.bridge.instance.getBooleanTopic(nt.SIM_ENABLE.name).publish()
    loops(robot, 0.1, lambda: robot.bridge.send_voltage((12.0, 0.0)))
    assert robot.voltage == (12.0, 0.0)
    enable.set(False)
    loops(robot, 0.2, lambda: robot.bridge.send_voltage((12.0, 0.0)))
    assert robot.voltage == (0.0, 0.0)
    time.sleep(0.05)
    assert robot.bridge.readings[nt.ENABLED].get() is False
    enable.set(True)
    loops(robot, 0.1, lambda: robot.bridge.send_voltage((5.0, 1.0)))
    assert robot.voltage == (5.0, 1.0)


def test_a_setpoint_with_feedforward_holds_the_arm_on_the_robot_s_loop(robot):
    """Mode setpoint: the robot closes the loop itself (PD + the model's feedforward), and
    the arm, off its support, stays where it is told."""
    feedforward = SetpointFeedforward(ArmDynamics(robot.arm), robot.arm.battery.nominal_voltage)
    hold = tuple(robot.plant.state[:2])

    def send():
        t = time.monotonic()
        robot.bridge.send_setpoint(hold, (0.0, 0.0), feedforward(t, hold, (0.0, 0.0)))
    loops(robot, 1.5, send)
    assert not robot.plant.resting
    assert np.max(np.abs(np.array(robot.plant.state[:2]) - hold)) < math.radians(1.0)


def test_readings_follow_the_contract(robot):
    loops(robot, 0.1)
    time.sleep(0.05)
    readings = {topic: robot.bridge.readings[topic].get() for topic in nt.ROBOT_READINGS}
    for topic in nt.ROBOT_READINGS:
        if topic.type == 'double[]':
            assert len(readings[topic]) == 2 and all(map(math.isfinite, readings[topic]))
    assert readings[nt.ENABLED] is True
    assert readings[nt.BUS_VOLTAGE] == robot.arm.battery.nominal_voltage
    # At 0 V and at rest on its support, no motor draws current.
    assert readings[nt.MOTOR_CURRENT] == [0.0, 0.0] and readings[nt.SUPPLY_CURRENT] == 0.0
    start = np.array(config.load('sim')[1].initial_position)
    assert np.max(np.abs(np.array(readings[nt.POSITION]) - start)) < math.radians(1.5)


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
        bridge = BridgeTables(client, 'test', 0, LOOPBACK, port)
        deadline = time.monotonic() + 10.0
        while not bridge.readings[nt.POSITION].readQueue() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert bridge.readings[nt.POSITION].get(), 'no readings from frc_robot_sim'
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
