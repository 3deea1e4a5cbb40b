"""The ntcore end of each side of the contract: the bridge's NT4 client, the robot's server.

Both send every value the moment it is set (``flush``), every one of them (``sendAll``: two
set within one NT period are not merged into the newer), and keep duplicates: a robot at
rest publishes the same reading every loop, and each one says it is alive.
"""

import math
from pathlib import Path
import socket
import tempfile

import ntcore

from arm_control.frc import contract as nt

LOOPBACK = '127.0.0.1'
SEND = ntcore.PubSubOptions(periodic=0.005, keepDuplicates=True, sendAll=True)
RECEIVE = ntcore.PubSubOptions(periodic=0.005, keepDuplicates=True, sendAll=True, pollStorage=50)


def now_us() -> int:
    """NT's clock (µs): the time base of every value's timestamp in this process."""
    return ntcore._now()


def _publisher(instance, topic: nt.NtTopic, options=SEND):
    return {'double[]': instance.getDoubleArrayTopic, 'double': instance.getDoubleTopic,
            'boolean': instance.getBooleanTopic, 'string': instance.getStringTopic,
            }[topic.type](topic.name).publish(options)


def _subscriber(instance, topic: nt.NtTopic, options=RECEIVE):
    getter, default = {'double[]': (instance.getDoubleArrayTopic, []),
                       'double': (instance.getDoubleTopic, math.nan),
                       'boolean': (instance.getBooleanTopic, False),
                       'string': (instance.getStringTopic, '')}[topic.type]
    return getter(topic.name).subscribe(default, options)


class BridgeTables:
    """The bridge's NT4 client: the robot's readings in, commands and the arm's state out."""

    def __init__(self, instance, identity: str, team_number: int, server_address: str,
                 port: int):
        self.instance = instance
        self.readings = {topic: _subscriber(instance, topic) for topic in nt.ROBOT_READINGS}
        self.voltage = _publisher(instance, nt.VOLTAGE_COMMAND)
        self.setpoint = [_publisher(instance, topic) for topic in nt.SETPOINT_COMMAND]
        self.state = _publisher(instance, nt.ARM_STATE)
        instance.startClient4(identity)
        if team_number:
            instance.setServerTeam(team_number, port)
        else:
            instance.setServer(server_address, port)

    def connected(self) -> bool:
        return self.instance.isConnected()

    def send_voltage(self, voltage) -> None:
        self.voltage.set([float(v) for v in voltage])
        self.instance.flush()

    def send_setpoint(self, position, velocity, feedforward_v) -> None:
        """The three parts with one timestamp, so the robot sees one command."""
        sent_us = now_us()
        for publisher, values in zip(self.setpoint, (position, velocity, feedforward_v)):
            publisher.set([float(v) for v in values], sent_us)
        self.instance.flush()

    def send_state(self, state: str) -> None:
        self.state.set(state)
        self.instance.flush()

    def close(self) -> None:
        """Stop the client and ntcore's threads (their listeners with them)."""
        self.instance.stopClient()
        ntcore.NetworkTableInstance.destroy(self.instance)


class RobotTables:
    """A robot's NT4 server on the loopback interface: readings out, commands in."""

    def __init__(self, instance, port: int):
        _check_port_free(port)
        self.instance = instance
        self.readings = {topic: _publisher(instance, topic) for topic in nt.ROBOT_READINGS}
        self.true_state = _publisher(instance, nt.TRUE_STATE)
        self.voltage = _subscriber(instance, nt.VOLTAGE_COMMAND)
        self.setpoint = [_subscriber(instance, topic) for topic in nt.SETPOINT_COMMAND]
        self.enable = _subscriber(instance, nt.SIM_ENABLE)
        # NT4 keeps "persistent" topics in a file; a stand-in keeps none.
        self._persist_dir = tempfile.TemporaryDirectory(prefix='frc_robot_sim_')
        persist_file = Path(self._persist_dir.name) / 'networktables.json'
        persist_file.write_text('[]')
        instance.startServer(str(persist_file), LOOPBACK, 0, port)     # 0: no NT3 port

    def publish(self, topic: nt.NtTopic, value, time_us: int = 0) -> None:
        self.readings[topic].set(value, time_us)

    def close(self) -> None:
        """Stop the server and ntcore's threads (their listeners with them)."""
        self.instance.stopServer()
        ntcore.NetworkTableInstance.destroy(self.instance)
        self._persist_dir.cleanup()


def _check_port_free(port: int) -> None:
    """ntcore does not say when it cannot listen: find out first, and say so."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)   # as ntcore's listener
        try:
            probe.bind((LOOPBACK, port))
        except OSError as error:
            raise OSError(f'cannot serve NT4 on {LOOPBACK}:{port}: {error.strerror}') from error


def free_port() -> int:
    """A TCP port on the loopback interface that nothing listens on now (for tests)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind((LOOPBACK, 0))
        return probe.getsockname()[1]
