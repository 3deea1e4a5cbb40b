"""What a team's coprocessor sees: how soon a first goal is reached after the nodes start,
and the share of one core each process takes, holding still and touring.

The installed sim, planner and controller (``test/rigs/arm_rig.py``'s ArmRig) start together on a
ROS domain of their own, ``--starts`` times. A goal (``mid_score``) is published once, as soon
as the controller subscribes to ``goal_point``: the bench says whether it was kept or refused.
If refused, it is sent again once the controller's diagnostics say it reaches the planner, as
the ``arm`` tool and the tour do. Times are from the start of the processes ("planner
available": when the controller said so on ``~/events``), with the CPU seconds each process
had used when the first goal was reached (the machine may be shared: those depend less on
its load than the wall times). After the last start, and ``--settle`` seconds (the keeper
times the paths between presets once the arm is idle), the CPU each process and its
children used over ``--seconds`` of holding still, and over ``--seconds`` of touring the
presets, as a share of one core. The plan worker and its keeper are the controller's
children, shown on their own rows.

    python bench/coprocessor.py                  # with install/setup.bash sourced
    python bench/coprocessor.py --starts 1       # one start (the default: 3)
    python bench/coprocessor.py --load           # two busy loops beside it (busy.py)
    python bench/coprocessor.py --write-docs     # keep the table in docs/benchmarks/
"""

import argparse
import os
from pathlib import Path
import sys
import tempfile
import time

BENCH = Path(__file__).resolve().parent
sys.path[:0] = [str(BENCH), str(BENCH.parent / 'test' / 'rigs'), str(BENCH.parent)]

import busy  # noqa: E402
import docs_table  # noqa: E402

from arm_control import config  # noqa: E402

GOAL = 'mid_score'
TOUR = ('high_score', 'back_score', 'floor_pickup', 'stow', 'mid_score')


def children(pid: int) -> list:
    """Every process whose parent is ``pid`` (from /proc)."""
    found = []
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / 'stat').read_text()
            except OSError:
                continue
            if int(stat.rsplit(')', 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
    return found


def label(pid: int, parent: str) -> str:
    try:
        command = (Path(f'/proc/{pid}') / 'cmdline').read_bytes().split(b'\0')
    except OSError:
        return f'{parent} child'
    words = [w.decode(errors='replace') for w in command]
    if any('plan_worker' in w for w in words):
        return 'keeper' if '--keeper' in words else 'plan worker'
    return f'{parent} child'


def processes(rig) -> dict:
    """{row name: pid} for the three nodes and their children, grandchildren included."""
    rows = {}
    for name in rig.NODES:
        pid = rig.processes[name].process.pid
        rows[name] = pid
        queue = [pid]
        while queue:
            for child in children(queue.pop()):
                rows[label(child, name)] = child
                queue.append(child)
    return rows


def shares(rig, seconds: float, during=None) -> dict:
    """Share of one core each process used over ``seconds`` (``during``: called meanwhile)."""
    from arm_rig import cpu_s
    rows = processes(rig)
    before = {row: cpu_s(pid) for row, pid in rows.items()}
    began = time.monotonic()
    while time.monotonic() - began < seconds:
        if during is not None:
            during()
        rig.spin_for(0.1)
    elapsed = time.monotonic() - began
    used = {}
    for row, pid in rows.items():
        try:
            used[row] = (cpu_s(pid) - before[row]) / elapsed
        except OSError:
            used[row] = float('nan')
    return used


def first_goal(rig, started: float, timeout_s: float) -> dict:
    """Times from ``started``: the controller subscribed, the planner available to it, the
    first goal reached; and whether the goal sent at subscription was kept."""
    from arm_control.nodes.common import controller_sees_planner
    presets = {name: (x, y) for name, x, y in config.load('controller')[0].presets}
    x, y = presets[GOAL]
    times = {}
    rig.spin_until(lambda: rig.goal_pub.get_subscription_count() > 0, timeout_s)
    times['controller subscribed'] = time.monotonic() - started
    sent = time.monotonic()
    rig.send(x, y)
    rig.spin_until(lambda: rig.said('goal_queued', sent) or rig.said('goal_accepted', sent)
                   or rig.said('goal_rejected', sent), timeout_s)
    times['first goal kept'] = not rig.said('goal_rejected', sent)

    def planner_seen() -> bool:
        return bool(rig.said('planner_available')) or any(
            controller_sees_planner(m, '/controller') for _, m in rig.diagnostics)
    rig.spin_until(planner_seen, timeout_s)
    # The event when it was heard (the diagnostics come once a second).
    times['planner available'] = (rig.said_at('planner_available') if rig.said(
        'planner_available') else time.monotonic()) - started
    if times['first goal kept']:
        rig.spin_until(lambda: rig.said('goal_reached', sent) or rig.said('goal_failed', sent),
                       timeout_s)
    failed = rig.said('goal_failed', sent)
    times['first goal carried out'] = times['first goal kept'] and not failed
    times['why not'] = (failed or rig.said('goal_rejected', sent) or [('', '', '')])[0][2]
    if not times['first goal carried out']:
        sent = time.monotonic()
        rig.send(x, y)
    rig.spin_until(lambda: rig.said('goal_reached', sent) or rig.said('goal_failed', sent),
                   timeout_s)
    reached = rig.said('goal_reached', sent)
    times['first goal reached'] = (rig.said_at('goal_reached', sent) - started
                                   if reached else float('nan'))
    times['CPU s'] = cpu_used(rig)
    return times


def cpu_used(rig) -> dict:
    """{row: CPU seconds each process has used since it started}."""
    from arm_rig import cpu_s
    used = {}
    for row, pid in processes(rig).items():
        try:
            used[row] = cpu_s(pid)
        except OSError:
            used[row] = float('nan')
    return used


def tour_step(rig, presets):
    """Send the next preset whenever the arm holds."""
    state = {'index': 0, 'sent': -1e9}

    def step():
        if rig.state in ('holding', 'waiting', 'error') \
                and time.monotonic() - state['sent'] > 0.3:
            name = TOUR[state['index'] % len(TOUR)]
            rig.send(*presets[name])
            state['index'] += 1
            state['sent'] = time.monotonic()
    return step


def fate(times: dict) -> str:
    return ('carried out' if times['first goal carried out'] else
            f"kept, then failed ({times['why not']})" if times['first goal kept'] else
            f"refused ({times['why not']})")


def table(starts: list, holding: dict, touring: dict, load: bool) -> str:
    """``starts``: each start's ``first_goal`` times, with the machine's ``load average``."""
    columns = ' | '.join(f'start {k + 1}' for k in range(len(starts)))
    rule = '|---' * (len(starts) + 1) + '|'
    lines = [f"load: {'two busy loops' if load else 'none added'}", '',
             f'| from the start, s | {columns} |', rule]

    def row(name, cells):
        lines.append(f'| {name} | ' + ' | '.join(cells) + ' |')
    for key in ('controller subscribed', 'planner available', 'first goal reached'):
        row(key, [f'{times[key]:.2f}' for times in starts])
    row('the goal sent at subscription', [fate(times) for times in starts])
    row("the machine's load average over the minute before",
        [f"{times['load average']:.1f}" for times in starts])
    names = sorted({r for times in starts for r in times['CPU s']},
                   key=lambda r: (r == 'sim', r))
    lines += ['', f'| CPU s to the first goal reached | {columns} |', rule]
    for name in names:
        row(name, [f"{times['CPU s'].get(name, 0.0):.2f}" for times in starts])
    row('all but the sim', [f"{sum(v for r, v in times['CPU s'].items() if r != 'sim'):.2f}"
                            for times in starts])
    lines += ['', f'| process, after start {len(starts)} | holding still, % of a core | '
              'touring, % of a core |', '|---|---|---|']
    for name in sorted(set(holding) | set(touring), key=lambda r: (r == 'sim', r)):
        lines.append(f'| {name} | {100 * holding.get(name, float("nan")):.1f} | '
                     f'{100 * touring.get(name, float("nan")):.1f} |')
    others = [r for r in holding if r != 'sim']
    lines.append(f'| all but the sim | {100 * sum(holding[r] for r in others):.1f} | '
                 f'{100 * sum(touring.get(r, 0.0) for r in others):.1f} |')
    return '\n'.join(lines)


def one_start(args, shares_too: bool):
    """The nodes started on a domain of their own: the first goal's times, and (``shares_too``)
    the shares of a core holding still and touring."""
    from arm_rig import ArmRig
    from ros_harness import Probe, ros_domain
    load_average = os.getloadavg()[0]
    holding = touring = {}
    with ros_domain() as domain, tempfile.TemporaryDirectory() as logs:
        probe = Probe(domain)
        rig = ArmRig(domain, probe, Path(logs))
        try:
            started = time.monotonic()
            rig.start_all()
            times = first_goal(rig, started, 60.0)
            if shares_too:
                rig.spin_for(args.settle)
                holding = shares(rig, args.seconds)
                presets = {n: (x, y) for n, x, y in config.load('controller')[0].presets}
                touring = shares(rig, args.seconds, tour_step(rig, presets))
        finally:
            rig.close()
            probe.close()
    return {**times, 'load average': load_average}, holding, touring


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--starts', type=int, default=3,
                        help='start the nodes this many times (the shares: the last)')
    parser.add_argument('--seconds', type=float, default=10.0, help='each measurement (s)')
    parser.add_argument('--settle', type=float, default=8.0,
                        help='idle before holding is measured, for the keeper (s)')
    parser.add_argument('--load', action='store_true', help='two busy loops beside it')
    parser.add_argument('--write-docs', action='store_true',
                        help='keep the table in docs/benchmarks/coprocessor.md')
    args = parser.parse_args()
    loops = busy.start(2, 3600.0) if args.load else []
    starts = []
    try:
        for k in range(args.starts):
            times, holding, touring = one_start(args, k == args.starts - 1)
            starts.append(times)
    finally:
        busy.stop(loops)
    text = table(starts, holding, touring, args.load)
    print(text)
    if args.write_docs:
        command = 'python bench/coprocessor.py' + (' --load' if args.load else '')
        name = 'coprocessor_loaded' if args.load else 'coprocessor'
        title = 'The coprocessor: first goal after start, CPU per process' + (
            ', two busy loops' if args.load else '')
        print(docs_table.write(name, title, command, text))


if __name__ == '__main__':
    main()
