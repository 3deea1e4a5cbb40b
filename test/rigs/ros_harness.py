"""Run installed executables as separate processes and probe them over DDS.

Each test takes a ROS domain of its own, held by a lock file for as long as it runs, so
parallel runs on one machine never hear each other; discovery stays on localhost.
"""

import contextlib
import ctypes
import fcntl
import itertools
import os
from pathlib import Path
import signal
import subprocess
import tempfile
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor

from arm_control.nodes.common import localhost_udp_environment

PACKAGE = 'arm_control'
# The probe and the processes started here: discovery on this machine only, over the nodes'
# transport (see use_udp_transport).
os.environ.update(localhost_udp_environment())
DOMAIN_IDS = range(1, 102)       # 0 is the default everyone shares; 101 is the last safe one
PR_SET_PDEATHSIG = 1             # prctl(2)
_TURNS = itertools.count(0, 7)   # each ros_domain() of this process starts its search further on
RESEND_S = 3.0                   # an idempotent call unanswered this long is sent again


def stamp_s(message) -> float:
    """A message's header stamp, in seconds."""
    return message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec


def lasting(messages, span_s: float) -> list:
    """The messages of the last ``span_s`` by their stamps; [] until they span that long
    (so that a wait means the same time whatever the topic's rate)."""
    if messages:
        newest = stamp_s(messages[-1])
        for k in range(len(messages) - 1, -1, -1):
            if stamp_s(messages[k]) <= newest - span_s:
                return messages[k:]
    return []


@contextlib.contextmanager
def ros_domain():
    """An unused ROS_DOMAIN_ID, locked against other test processes until released."""
    lock_dir = Path(tempfile.gettempdir()) / 'arm_control_ros_domains'
    lock_dir.mkdir(exist_ok=True)
    # A domain of its own for each test in turn, not the one the last test released: a node
    # of the last test still going away must not be heard by the next.
    start = (os.getpid() + next(_TURNS)) % len(DOMAIN_IDS)
    for offset in range(len(DOMAIN_IDS)):
        domain = DOMAIN_IDS[(start + offset) % len(DOMAIN_IDS)]
        handle = open(lock_dir / f'{domain}.lock', 'w')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        try:
            yield domain
        finally:
            handle.close()
        return
    raise RuntimeError('every ROS domain id is taken by another test process')


def install_prefix() -> Path:
    """The install prefix holding lib/arm_control (from AMENT_PREFIX_PATH)."""
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix and (Path(prefix) / 'lib' / PACKAGE).is_dir():
            return Path(prefix)
    raise RuntimeError('arm_control is not installed on AMENT_PREFIX_PATH: '
                       'run the tests with `colcon test` after `colcon build`')


def ros_environment(domain: int) -> dict:
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain),
               PYTHONUNBUFFERED='1', RCUTILS_COLORIZED_OUTPUT='0')
    return env


def _end_with_parent() -> None:
    """In the child before exec: SIGINT when the process that started it ends, however it
    ends. A test run killed from outside had left its nodes running, loading the machine
    under the next runs' measurements."""
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGINT)


class NodeProcess:
    """An installed executable, ``ros2 run arm_control <name>`` style, in its own process."""

    def __init__(self, name: str, domain: int, ros_args=(), log_dir: Path | None = None,
                 environment: dict | None = None):
        """``environment``: variables to set on top of the domain's, or to unset (None)."""
        self.name = name
        executable = install_prefix() / 'lib' / PACKAGE / name
        self.log_path = Path(log_dir or tempfile.mkdtemp()) / f'{name}.log'
        self.log = open(self.log_path, 'w')
        command = [str(executable)]
        if ros_args:
            command += ['--ros-args', *ros_args]
        env = ros_environment(domain)
        for variable, value in (environment or {}).items():
            if value is None:
                env.pop(variable, None)
            else:
                env[variable] = value
        self.process = subprocess.Popen(command, env=env, stdout=self.log,
                                        stderr=subprocess.STDOUT, start_new_session=True,
                                        preexec_fn=_end_with_parent)

    def output(self) -> str:
        if not self.log.closed:
            self.log.flush()
        return self.log_path.read_text()

    def alive(self) -> bool:
        return self.process.poll() is None

    def stop(self, timeout_s: float = 10.0) -> int:
        if self.alive():
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, signal.SIGKILL)
                self.process.wait()
        self.log.close()
        return self.process.returncode


class Probe:
    """A node in the test process, on the test's domain, that waits for things with a timeout."""

    def __init__(self, domain: int, name: str = 'probe'):
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_until(self, condition, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if condition():
                return True
            self.executor.spin_once(timeout_sec=0.05)
        return condition()

    def spin_for(self, duration_s: float) -> None:
        self.spin_until(lambda: False, duration_s)

    def collect(self, msg_type, topic: str, qos=10) -> list:
        """Subscribe and return the list that received messages are appended to."""
        received = []
        self.node.create_subscription(msg_type, topic, received.append, qos)
        return received

    def call(self, srv_type, name: str, request, timeout_s: float = 10.0,
             idempotent: bool = False):
        """One call on a new client. ``idempotent``: ask again every ``RESEND_S`` until
        answered. A new client is ready once it sees the server, but the server may not see
        the client yet: under load rmw_fastrtps then drops the answer ("failed to send
        response (timeout)") and the call would wait out its timeout."""
        # The client goes with the call: the serving process keeps about 15 KB for every
        # client endpoint alive, so one left behind per call looks like a leak in it.
        client = self.node.create_client(srv_type, name)
        try:
            if not self.spin_until(client.service_is_ready, timeout_s):
                raise TimeoutError(f'service {name} did not appear within {timeout_s} s')
            deadline = time.monotonic() + timeout_s
            futures = [client.call_async(request)]
            while not any(f.done() for f in futures) and time.monotonic() < deadline:
                self.spin_until(lambda: any(f.done() for f in futures),
                                min(RESEND_S, deadline - time.monotonic()) if idempotent
                                else deadline - time.monotonic())
                if idempotent and not any(f.done() for f in futures):
                    futures.append(client.call_async(request))
            done = [f for f in futures if f.done()]
            if not done:
                raise TimeoutError(f'service {name} did not answer within {timeout_s} s')
            return done[0].result()
        finally:
            self.node.destroy_client(client)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
