"""The latency frc_bridge adds, in each direction, on one machine.

This process plays both ends: the robot (an NT4 server on a free loopback port, readings at
50 Hz, enabled) and a ROS process (a probe on its own ROS domain). The installed
``frc_bridge`` runs between them as a process of its own. Every sample carries its number,
so each arrival is matched with its own sending on this process's one clock:

- robot -> ROS: a reading published on NT (and flushed) -> ``joint_states`` heard here;
- ROS -> robot: ``voltage_command`` published here -> the value seen on the robot's NT.

Both flows run at 50 Hz at once, as they do in use. (The times NT values carry are not used
here: they hang on NT's clock synchronisation, which a loaded machine skews by milliseconds.)

    python bench/bench_frc_bridge.py                 # 20 s
    python bench/bench_frc_bridge.py --seconds 60

Needs the package built and sourced (``ros_harness`` finds it on AMENT_PREFIX_PATH).
Not a test: it prints a table.
"""

import argparse
from pathlib import Path
import sys
import tempfile
import threading
import time

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / 'test' / 'rigs'), str(HERE.parent)]

import ntcore  # noqa: E402
import numpy as np  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from arm_control.frc import contract as nt  # noqa: E402
from arm_control.frc.codec import encode_reading, Reading  # noqa: E402
from arm_control.frc.tables import free_port, now_us, RobotTables  # noqa: E402
from arm_control.nodes.common import COMMANDS, STATE_STREAM  # noqa: E402

PERIOD_S = nt.LOOP_PERIOD_S
SEQUENCE_RAD = 1e-4         # sample k is sent as position [k·1e-4 rad, 0] ...
SEQUENCE_V = 1e-3           # ... and as voltage [k·1e-3 V, 0]
WARM_UP_S = 2.0             # samples before this are not counted (discovery, first plans)


def robot_loop(tables: RobotTables, sent: dict, stop: threading.Event) -> None:
    """The robot's 50 Hz loop: readings numbered, enabled, flushed."""
    k = 0
    next_s = time.monotonic()
    while not stop.is_set():
        k += 1
        sent[k] = time.monotonic()
        time_us = now_us()
        tables.publish(encode_reading(Reading(time_us, True, (k * SEQUENCE_RAD, 0.0),
                                              (0.0, 0.0))), (0.0,) * 4, time_us)
        next_s += PERIOD_S
        stop.wait(max(0.0, next_s - time.monotonic()))


def percentiles(latencies_s) -> str:
    ms = 1e3 * np.asarray(latencies_s)
    if not len(ms):
        return '| 0 | - | - | - |'
    return f'| {len(ms)} | {np.median(ms):.2f} | {np.percentile(ms, 99):.2f} | {ms.max():.2f} |'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--seconds', type=float, default=20.0)
    seconds = parser.parse_args().seconds
    from arm_rig import cpu_s
    from ros_harness import NodeProcess, Probe, ros_domain

    port = free_port()
    tables = RobotTables(ntcore.NetworkTableInstance.create(), port)
    readings_sent, readings_heard = {}, {}
    commands_sent, commands_seen = {}, {}

    def on_command(event) -> None:               # ntcore's thread: a command reached the robot
        arrived_s = time.monotonic()
        value = event.data.value
        k = round(value.getDoubleArray()[1] / SEQUENCE_V)
        if k > 0 and k not in commands_seen:
            commands_seen[k] = arrived_s
    listener = tables.instance.addListener(tables.command, ntcore.EventFlags.kValueRemote,
                                           on_command)

    with ros_domain() as domain, tempfile.TemporaryDirectory() as log_dir:
        probe = Probe(domain, 'bench_frc_bridge')
        bridge = NodeProcess('frc_bridge', domain, ['-p', f'nt_port:={port}'], Path(log_dir))
        node = probe.node

        def on_joint_states(message: JointState) -> None:
            arrived_s = time.monotonic()
            k = round(message.position[0] / SEQUENCE_RAD)
            if k not in readings_heard:
                readings_heard[k] = arrived_s
        node.create_subscription(JointState, 'joint_states', on_joint_states, STATE_STREAM)
        voltage_pub = node.create_publisher(Float64MultiArray, 'voltage_command', COMMANDS)
        command_k = [0]

        def send_command() -> None:
            command_k[0] += 1
            k = command_k[0]
            commands_sent[k] = time.monotonic()
            voltage_pub.publish(Float64MultiArray(data=[k * SEQUENCE_V, 0.0]))

        stop = threading.Event()
        robot = threading.Thread(target=robot_loop, args=(tables, readings_sent, stop))
        robot.start()
        try:
            if not probe.spin_until(lambda: len(readings_heard) > 10, 30.0):
                raise SystemExit(f'the bridge sends no joint_states:\n{bridge.output()}')
            node.create_timer(PERIOD_S, send_command)
            began, cpu_began = time.monotonic(), cpu_s(bridge.process.pid)
            probe.spin_for(seconds + 0.5)
            cpu_share = (cpu_s(bridge.process.pid) - cpu_began) / (time.monotonic() - began)
        finally:
            stop.set()
            robot.join()
            bridge.stop()
            bridge_said = bridge.output()
            probe.close()
            tables.instance.removeListener(listener)
            tables.close()

    def latencies(sent, heard, since_s):
        return [heard[k] - sent[k] for k in sent if k in heard and sent[k] >= since_s]
    counted = began + WARM_UP_S
    up = latencies(readings_sent, readings_heard, counted)
    down = latencies(commands_sent, commands_seen, counted)
    lost_up = sum(1 for k, t in readings_sent.items() if t >= counted and t < began + seconds
                  and k not in readings_heard)
    lost_down = sum(1 for k, t in commands_sent.items()
                    if counted <= t < began + seconds and k not in commands_seen)
    print(f'frc_bridge latency over {seconds - WARM_UP_S:g} s at 50 Hz each way; never '
          f'arrived: {lost_up} readings, {lost_down} commands; the bridge lost the robot '
          f"{bridge_said.count('lost the robot')} times; it used {100 * cpu_share:.0f} % of "
          'a core\n')
    print('| path | samples | p50 ms | p99 ms | max ms |')
    print('|---|---|---|---|---|')
    rows = [('robot reading on NT → `joint_states` heard by another ROS process', up),
            ("`voltage_command` published → seen on the robot's NT", down)]
    for name, latencies_s in rows:
        print(f'| {name} {percentiles(latencies_s)}')


if __name__ == '__main__':
    main()
