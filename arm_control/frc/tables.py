"""The ntcore end of each side of the contract: the bridge's NT4 client, the robot's server.

Both send every value the moment it is set (``flush``), every one of them (``sendAll``: two
set within one NT period are not merged into the newer), and keep duplicates: a robot at
rest publishes the same reading every loop, and each one says it is alive.
"""

import math
from pathlib import Path
import socket
import tempfile
import threading

import ntcore

from arm_control.frc import contract as nt

LOOPBACK = '127.0.0.1'
SEND = ntcore.PubSubOptions(periodic=0.005, keepDuplicates=True, sendAll=True)
RECEIVE = ntcore.PubSubOptions(periodic=0.005, keepDuplicates=True, sendAll=True, pollStorage=50)
DRAW_PERIOD_S = 0.04        # drawing (Mechanism2d) goes out at most this often, never flushed
DRAW = ntcore.PubSubOptions(periodic=DRAW_PERIOD_S)


class _NtClock:
    """NT's clock (µs), through public API only: ntcore stamps a value set with time 0
    with its own now. A private instance that is never started: nothing goes on the network."""

    def __init__(self):
        self.instance = ntcore.NetworkTableInstance.create()
        topic = self.instance.getIntegerTopic('/clock')
        options = ntcore.PubSubOptions(keepDuplicates=True)
        self.publisher = topic.publish(options)
        self.subscriber = topic.subscribe(0, options)
        self.lock = threading.Lock()

    def now_us(self) -> int:
        with self.lock:
            self.publisher.set(0)
            return self.subscriber.getAtomic().time


_CLOCK = _NtClock()


def now_us() -> int:
    """NT's clock (µs): the time base of every value's timestamp in this process (on the
    server, the server clock itself)."""
    return _CLOCK.now_us()


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
    """The bridge's NT4 client: the robot's readings in, commands and the arm's state out.

    Commands are flushed the moment they are set, on a connection that carries nothing
    else of size; drawing (``drawing``, for the Mechanism2d) has a connection of its own,
    sent at ntcore's own pace and never flushed, so a command never waits behind it.
    """

    def __init__(self, instance, identity: str, team_number: int, server_address: str,
                 port: int, drawing: bool = True):
        self.instance = instance
        self.reading = _subscriber(instance, nt.READING)
        self.command = _publisher(instance, nt.COMMAND)
        self.state = _publisher(instance, nt.ARM_STATE)
        self.drawing = ntcore.NetworkTableInstance.create() if drawing else None
        self.identity, self.server = identity, (team_number, server_address, port)
        for client, name in ((instance, identity), (self.drawing, f'{identity} drawing')):
            if client is not None:
                self._dial(client, name)

    def _dial(self, client, name: str) -> None:
        team_number, server_address, port = self.server
        client.startClient4(name)
        if team_number:
            client.setServerTeam(team_number, port)
        else:
            client.setServer(server_address, port)

    def redial(self) -> None:
        """Try the server now: ntcore's own retries come about once a second; a restarted
        client tries at once (its publishers, subscribers and listeners stay)."""
        self.instance.stopClient()
        self._dial(self.instance, self.identity)

    def connected(self) -> bool:
        return self.instance.isConnected()

    def server_offset_us(self) -> int:
        """server clock − this process's NT clock (µs); 0 until ntcore has measured it."""
        return self.instance.getServerTimeOffset() or 0

    def server_now_us(self) -> int:
        return now_us() + self.server_offset_us()

    def send_command(self, values) -> None:
        """A command (``codec.encode_voltage``/``encode_profile``), flushed at once."""
        self.command.set([float(v) for v in values])
        self.instance.flush()

    def send_state(self, state: str) -> None:
        self.state.set(state)
        self.instance.flush()

    def close(self) -> None:
        """Stop the clients and ntcore's threads (their listeners with them)."""
        for client in (self.instance, self.drawing):
            if client is not None:
                client.stopClient()
                ntcore.NetworkTableInstance.destroy(client)


class RobotTables:
    """A robot's NT4 server on the loopback interface: readings out, commands in."""

    def __init__(self, instance, port: int):
        _check_port_free(port)
        self.instance = instance
        self.reading = _publisher(instance, nt.READING)
        self.true_state = _publisher(instance, nt.TRUE_STATE)
        self.command = _subscriber(instance, nt.COMMAND)
        self.enable = _subscriber(instance, nt.SIM_ENABLE)
        # NT4 keeps "persistent" topics in a file; a stand-in keeps none.
        self._persist_dir = tempfile.TemporaryDirectory(prefix='frc_robot_sim_')
        self._persist_file = Path(self._persist_dir.name) / 'networktables.json'
        self._persist_file.write_text('[]')
        self.port = port
        self.serve()

    def serve(self) -> None:
        """Serve NT4 (again, after ``stop_serving``: a robot that comes back)."""
        self.instance.startServer(str(self._persist_file), LOOPBACK, 0, self.port)  # 0: no NT3

    def stop_serving(self) -> None:
        """Drop every connection, as a robot that loses its network."""
        self.instance.stopServer()

    def publish(self, reading_values, true_state, time_us: int) -> None:
        """One loop's reading (and the sim's truth), stamped ``time_us``, flushed at once."""
        self.reading.set(reading_values, time_us)
        self.true_state.set([float(time_us), *true_state], time_us)
        self.instance.flush()

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
