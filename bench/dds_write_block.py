"""How long one DDS write can block while other nodes join the graph: plain rclpy, none of
arm_control's code.

A publisher process writes five JointState topics at 50 Hz from a SCHED_FIFO thread (where
allowed), a subscriber process reads them, and every 2 s a short-lived node joins the
domain, subscribes to one topic, pauses itself (a debugger, SIGSTOP, a process the
scheduler starves) and is resumed 2 s later. The table gives, per transport, QoS and load,
how many writes (``publish`` calls) took over 20 ms and over 100 ms, and the longest.
Discovery stays on this machine either way: as Jazzy's LOCALHOST range sets it up (shared
memory and UDP), or as the nodes do (the same discovery over UDP only,
config/fastdds_localhost_udp.xml). With shared memory, the first send to a new peer's port
checks the port's health, and a failed check (the peer is paused) sleeps 333 ms holding a
lock every send of the process waits on; rclpy holds Python's lock meanwhile, so the whole
process waits.

    python bench/dds_write_block.py                  # 60 s per row
    python bench/dds_write_block.py --seconds 30 --qos reliable
"""

import argparse
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

sys.path.insert(0, str(Path(__file__).resolve().parent))
import busy  # noqa: E402

from arm_control.nodes.common import localhost_udp_environment  # noqa: E402

TRANSPORTS = {'shared memory + UDP (LOCALHOST)': {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'},
              "UDP only (the nodes' profile)": localhost_udp_environment()}

TOPICS = 5
PERIOD_S = 0.02
CHURN_EVERY_S = 2.0
JOINER = ('import os, signal, time, rclpy; from rclpy.qos import qos_profile_sensor_data; '
          'from sensor_msgs.msg import JointState; rclpy.init(); '
          'node = rclpy.create_node("joiner"); '
          'node.create_subscription(JointState, "block_test_0", lambda _: None, '
          'qos_profile_sensor_data); '
          'time.sleep(0.2); os.kill(os.getpid(), signal.SIGSTOP); '
          'rclpy.spin_once(node, timeout_sec=0.5)')


def qos(reliability: str):
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    return QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE
                      if reliability == 'reliable' else ReliabilityPolicy.BEST_EFFORT)


def publish(reliability: str, seconds: float) -> None:
    """The writer: prints 'writes slow20 slow100 worst_ms'."""
    import rclpy
    from sensor_msgs.msg import JointState
    rclpy.init()
    node = rclpy.create_node('writer')
    writers = [node.create_publisher(JointState, f'block_test_{i}', qos(reliability))
               for i in range(TOPICS)]
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
    except OSError:
        pass
    message = JointState(name=['a', 'b'], position=[0.0, 0.0], velocity=[0.0, 0.0])
    time.sleep(2.0)                                  # matched before counting
    durations = []
    due = time.monotonic()
    end = due + seconds
    while due < end:
        due += PERIOD_S
        time.sleep(max(0.0, due - time.monotonic()))
        for writer in writers:
            began = time.monotonic()
            writer.publish(message)
            durations.append(time.monotonic() - began)
    print(len(durations), sum(d > 0.02 for d in durations), sum(d > 0.1 for d in durations),
          f'{1000 * max(durations):.0f}')


def subscribe(reliability: str, seconds: float) -> None:
    import rclpy
    from sensor_msgs.msg import JointState
    rclpy.init()
    node = rclpy.create_node('reader')
    for i in range(TOPICS):
        node.create_subscription(JointState, f'block_test_{i}', lambda _: None, qos(reliability))
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.1)


def row(transport: str, reliability: str, loaded: bool, seconds: float, domain: int) -> str:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), **TRANSPORTS[transport])
    for name in ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_BUILTIN_TRANSPORTS'):
        if name not in TRANSPORTS[transport]:
            env.pop(name, None)
    # The node that joins is a stock one (a user's `ros2 topic echo`): shared memory and UDP.
    joiner_env = dict(env, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    joiner_env.pop('FASTRTPS_DEFAULT_PROFILES_FILE', None)
    me = [sys.executable, __file__]
    load = busy.start(2, seconds + 30) if loaded else []
    try:
        reader = subprocess.Popen(me + ['--role', 'reader', reliability, str(seconds + 8)],
                                  env=env)
        writer = subprocess.Popen(me + ['--role', 'writer', reliability, str(seconds)],
                                  env=env, stdout=subprocess.PIPE, text=True)
        joiners = []
        time.sleep(3.0)
        while writer.poll() is None:
            joiners.append(subprocess.Popen([sys.executable, '-c', JOINER], env=joiner_env))
            time.sleep(CHURN_EVERY_S)
            joiners[-1].send_signal(signal.SIGCONT)
        joins = len(joiners)
        writes, slow20, slow100, worst = writer.stdout.read().split()
        reader.wait()                                # it ends by itself, soon after
    finally:
        busy.stop(load)
    load_name = 'two busy loops' if loaded else 'idle'
    reliability = reliability.replace('_', ' ')
    return (f'| {transport} | {reliability} | {load_name} | {joins} | {writes} | {slow20} '
            f'| {slow100} | {worst} |')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--seconds', type=float, default=60.0, help='per row')
    parser.add_argument('--domain', type=int,
                        default=int(os.environ.get('ROS_DOMAIN_ID', 0)))
    parser.add_argument('--qos', choices=('reliable', 'best_effort'), nargs='+',
                        default=['reliable', 'best_effort'])
    parser.add_argument('--role', nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role:
        role, reliability, seconds = args.role
        (publish if role == 'writer' else subscribe)(reliability, float(seconds))
        return
    print('| transport | QoS | load | nodes joined | writes | over 20 ms | over 100 ms '
          '| longest (ms) |')
    print('|---|---|---|---|---|---|---|---|')
    for loaded in (False, True):
        for reliability in args.qos:
            for transport in TRANSPORTS:
                print(row(transport, reliability, loaded, args.seconds, args.domain),
                      flush=True)


if __name__ == '__main__':
    main()
