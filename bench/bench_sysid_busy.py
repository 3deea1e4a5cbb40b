"""sysid through ROS beside busy processes: does every run complete, and hand the arm over?

Each run starts, on one ROS domain, the sim with the demo arm (a sensor-noise seed of its
own), ``sysid`` with its full excitation, and -- once ``identified_params.yaml`` is written
and the arm has been held ``HELD_S`` -- the controller on that file, which takes the arm
over. With ``--busy N`` (default 2), N busy loops (``busy.py``) load the cores throughout.
Per run it prints whether a file was written, sysid's exit code, the arm time and stalls it
reported, the largest motor current the sim reported while sysid commanded, the lowest
point of either link over the whole run (negative: in the floor) and how far the arm moved
from the hold once the controller took it.

    python bench/bench_sysid_busy.py --runs 5 --domain 224 [--busy 2] [--write-docs]
        [--arm bench/arms/heavy_offset.yaml] [--keep /tmp/runs]
"""

import argparse
import math
from pathlib import Path
import re
import sys
import tempfile
import time

BENCH = Path(__file__).resolve().parent
sys.path[:0] = [str(BENCH), str(BENCH.parent), str(BENCH.parent / 'test' / 'rigs')]

import busy  # noqa: E402
import docs_table  # noqa: E402
import numpy as np  # noqa: E402
from ros_harness import install_prefix, NodeProcess, Probe  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from arm_control import config  # noqa: E402
from arm_control.model.world import ForbiddenSpace  # noqa: E402

HELD_S = 3.0
AFTER_S = 3.0
TIMEOUT_S = 180.0


def share(name):
    return str(install_prefix() / 'share' / 'arm_control' / 'config' / name)


def one_run(domain, seed, directory, forbidden, arm_file):
    probe = Probe(domain, f'bench_sysid_busy_{seed}')
    truth, currents = [], []
    probe.node.create_subscription(JointState, '/sim/ground_truth',
                                   lambda m: truth.append((time.monotonic(), m)), 100)
    probe.node.create_subscription(Float64MultiArray, '/motor_currents',
                                   lambda m: currents.append((time.monotonic(), m)), 100)
    processes = [NodeProcess('sim', domain, ('--params-file', share('arm.yaml'),
                                             '--params-file', arm_file,
                                             '-p', f'random_seed:={seed}'), directory)]
    sysid = NodeProcess('sysid', domain, ('-p', f'output_directory:={directory}'), directory)
    processes.append(sysid)
    written = directory / 'identified_params.yaml'
    began = time.monotonic()
    row = {'seed': seed}
    try:
        probe.spin_until(lambda: written.exists() or not sysid.alive(), TIMEOUT_S)
        row['file'] = written.exists()
        if row['file']:
            probe.spin_for(HELD_S)
            handing = time.monotonic()
            held = np.array(truth[-1][1].position)
            processes.append(NodeProcess('controller', domain, (
                '--params-file', share('arm.yaml'), '--params-file', str(written)), directory))
            probe.spin_until(lambda: not sysid.alive(), 30.0)
            probe.spin_for(AFTER_S)
            after = np.array([m.position for t, m in truth if t >= handing]).reshape(-1, 2)
            row['moved_deg'] = math.degrees(float(np.max(np.abs(after - held))))
        else:
            handing = time.monotonic()
        row['code'] = sysid.process.poll()
        output = sysid.output()
        done = re.search(r'excitation done in ([\d.]+) s of arm time .*?(\d+) stalls', output)
        row['arm_s'] = float(done.group(1)) if done else math.nan
        row['stalls'] = int(done.group(2)) if done else -1
        row['stopped'] = 'excitation stopped' in output
        amps = [np.abs(m.data) for t, m in currents if began <= t <= handing]
        row['peak_a'] = float(np.max(amps)) if amps else math.nan
        q = np.array([m.position for _, m in truth]).reshape(-1, 2)
        row['lowest_mm'] = 1000 * float(np.min(forbidden.lowest_point_m(q))) if len(q) else \
            math.nan
        row['wall_s'] = time.monotonic() - began
    finally:
        for process in reversed(processes):
            process.stop()
        probe.close()
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=5)
    parser.add_argument('--busy', type=int, default=2)
    parser.add_argument('--domain', type=int, required=True)
    parser.add_argument('--arm', default=share('sysid_demo_arm.yaml'),
                        help='the true arm: a parameter file layered over arm.yaml for the sim')
    parser.add_argument('--keep', default='', help='keep each run (log.mcap, files) here')
    parser.add_argument('--write-docs', action='store_true')
    args = parser.parse_args()
    forbidden = ForbiddenSpace(config.load('sim')[0])
    loops = busy.start(args.busy, 3600.0) if args.busy else []
    rows = []
    try:
        for k in range(args.runs):
            if args.keep:
                folder = Path(args.keep) / f'run{k + 1}'
                folder.mkdir(parents=True, exist_ok=True)
                rows.append(one_run(args.domain, 10 + k, folder, forbidden, args.arm))
            else:
                with tempfile.TemporaryDirectory() as folder:
                    rows.append(one_run(args.domain, 10 + k, Path(folder), forbidden,
                                        args.arm))
            print(rows[-1], flush=True)
    finally:
        busy.stop(loops)
    lines = [f'{args.runs} runs of sysid through ROS beside {args.busy} busy loops '
             f'(the true arm: arm.yaml with {Path(args.arm).name}; then the controller on the '
             'identified file takes over):', '',
             '| run | file written | exit code | arm time s | stalls ridden | stopped | '
             'peak motor A | lowest point mm | moved after hand-over deg |',
             '|---|---|---|---|---|---|---|---|---|']
    for k, r in enumerate(rows):
        lines.append(f"| {k + 1} | {'yes' if r['file'] else 'no'} | {r['code']} | "
                     f"{r['arm_s']:.1f} | {r['stalls']} | {'yes' if r['stopped'] else 'no'} | "
                     f"{r['peak_a']:.1f} | {r['lowest_mm']:.0f} | "
                     f"{r.get('moved_deg', math.nan):.2f} |")
    table = '\n'.join(lines)
    print(table)
    if args.write_docs:
        docs_table.write('sysid_busy', 'sysid beside busy loops, through ROS',
                         'python bench/bench_sysid_busy.py ' + ' '.join(sys.argv[1:]), table)


if __name__ == '__main__':
    main()
