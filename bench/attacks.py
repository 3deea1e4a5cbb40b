"""The attacks of issues 12 and 39 ("never drop the arm"), run on the installed processes
(the second suite, what reaches the nodes while they run, is in bench/attacks_live.py).

sim, planner and controller run as separate processes on a ROS domain of their own (as the
process tests run them, through test/rigs/arm_rig.py); this process attacks them one attack at
a time, each on a reset arm (or a fresh one, after an attack that leaves the nodes
changed), and listens. One markdown table comes out, a row per attack:

- lowest point (mm) of either link: min over the elbow point and the tool point of y on
  ``/sim/ground_truth`` (the shoulder pivot is at floor level, so below 0 is in the floor),
  counted over the samples while the controller was commanding (its state not no_sensors,
  estopped or disabled, and a ``voltage_command`` heard within the sim's
  ``command_timeout_s``), and over all samples;
- the control loop's period as heard here, in another process: the gaps between the DDS
  reception times (rclpy's message info) of ``voltage_command``, p50 / p99 / worst, the
  silences at the start and end of the attack included. The DDS threads that stamp them run
  at real-time priority where the system allows it, as the nodes' do;
- answers: goals answered (an event on ``controller/events`` taking or refusing it, or a
  summary event with a count) against goals sent; service calls answered for the e-stops;
- time to ready: after a controller restart, until it takes a goal again.

    python bench/attacks.py                  # every attack, a few minutes
    python bench/attacks.py --load           # ... with two busy loops on the machine
    python bench/attacks.py --only flood --seconds 4
    python bench/attacks.py --write-docs     # ... and keep the table in docs/benchmarks

Needs the package built and sourced (``ros_harness`` finds it on AMENT_PREFIX_PATH). Not a
test: it asserts nothing and prints a table. Node logs stay in the directory it names.
"""

import argparse
from contextlib import nullcontext
import math
import os
from pathlib import Path
import signal
import sys
import tempfile
import time

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / 'test' / 'rigs'), str(HERE)]

from arm_rig import ArmRig, BAD_GOALS, START_Q  # noqa: E402
from attack_rig import (ANSWERS, ARM, Bench, BIG, Listener, LISTENER_PRIORITY,  # noqa: E402
                        LOAD_BUDGET_S, lowest_points_mm, period_ms, point_of, PRESETS,
                        READY_TIMEOUT_S, short, SIM, y_lowest_m)
import attacks_live  # noqa: E402
import busy  # noqa: E402
import docs_table  # noqa: E402
from goal_flood import flood_goals  # noqa: E402
import numpy as np  # noqa: E402
from ros_harness import NodeProcess, Probe, ros_domain  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from arm_control import realtime  # noqa: E402
from arm_control.control.events import parse_event  # noqa: E402


def idle(b: Bench) -> dict:
    b.wait(b.seconds)
    return dict(done=f'the arm held {b.seconds:g} s, nothing sent')


def moves(b: Bench) -> dict:
    tour = ('mid_score', 'high_score', 'back_score', 'floor_pickup', 'stow')
    since, reached = time.time(), 0
    for name in tour:
        sent = time.time()
        b.send(*PRESETS[name])
        b.wait_until(lambda: b.heard.said(sent, 'goal_reached', 'goal_failed', 'goal_rejected'),
                     b.seconds)
        reached += bool(b.heard.said(sent, 'goal_reached'))
    return dict(done=f'goal_point tour {", ".join(tour)}, each once reached',
                answers=f'{b.heard.answers(since)}/{len(tour)}',
                notes=f'{reached} of {len(tour)} reached')


def oversized(b: Bench) -> dict:
    since = time.time()
    b.publish(b.preset_pub, String(data='x' * BIG))
    normal_s = time.time()
    b.publish(b.preset_pub, String(data='mid_score'))
    b.wait_until(lambda: b.heard.first_answer_s(normal_s, ANSWERS, "'mid_score'"),
                 max(30.0, b.seconds))
    normal_answer_s = b.heard.first_answer_s(normal_s, ANSWERS, "'mid_score'")
    big_goal_s = time.time()
    b.send(1.1, 0.9, frame='f' * BIG)
    b.wait_until(lambda: b.heard.first_answer_s(big_goal_s, ANSWERS), max(30.0, b.seconds))
    big_answer_s = b.heard.first_answer_s(big_goal_s, ANSWERS)
    b.wait(b.seconds / 2)
    b.fresh_next = True                 # what the controller keeps of the text stays with it

    def after(answer_s, sent_s):
        return f'answered after {answer_s - sent_s:.2f} s' if answer_s else 'never answered'
    return dict(done="10 MB goal_preset, then preset 'mid_score'; then a goal_point with a "
                     '10 MB frame_id',
                answers=f'{b.heard.answers(since)}/3',
                notes=f"'mid_score' {after(normal_answer_s, normal_s)}; the 10 MB frame_id "
                      f'{after(big_answer_s, big_goal_s)}')


def floor_line(b: Bench) -> dict:
    goals = ((1.8, 0.0), (1.2, 0.0))
    since = time.time()
    for goal in goals:
        b.send(*goal)
    b.wait_until(lambda: len(b.heard.said(since, 'goal_reached', 'goal_failed', 'goal_rejected'))
                 >= len(goals), 3 * b.seconds)
    b.wait(b.seconds / 2)
    outcomes = ['reached' if text.startswith('goal_reached') else text[:80]
                for text in b.heard.said(since, 'goal_reached', 'goal_failed', 'goal_rejected')]
    return dict(done='goal_point (1.8, 0.0), then (1.2, 0.0), in arm_base',
                answers=f'{b.heard.answers(since)}/{len(goals)}',
                notes=f"outcomes: {', '.join(outcomes) or 'none heard'}")


def estop_burst(b: Bench, pairs: int = 50) -> dict:
    began, answered = time.monotonic(), 0
    for _ in range(pairs):
        for client in (b.estop, b.reset):
            answered += b.call(client) is not None
    took_s = time.monotonic() - began
    b.wait(b.seconds / 2)
    return dict(done=f'{pairs} controller/estop + controller/reset pairs, each call as soon '
                     f'as the last was answered ({took_s:.1f} s)',
                answers=f'{answered}/{2 * pairs} calls', notes=f'then {b.rig.state}')


def graph_churn(b: Bench, nodes: int = 20) -> dict:
    lifetime_s = 1.0
    churn = b.child('churn', nodes, lifetime_s, max(b.seconds, 2.0) / nodes)
    log_dir = b.rig.log_dir / f'arm2_{len(b.children)}'
    log_dir.mkdir(parents=True, exist_ok=True)
    began = time.monotonic()
    arm2 = [NodeProcess(name, b.rig.domain, ('-r', '__ns:=/arm2'), log_dir)
            for name in ArmRig.NODES]
    b.heard.arm2_state = ''
    up = b.wait_until(lambda: b.heard.arm2_state == 'waiting', 60.0)
    up_s = time.monotonic() - began
    b.wait(2.0)
    for process in arm2:
        process.stop()
    b.wait_until(lambda: churn.poll() is not None, 30.0)
    b.wait(b.seconds / 4)
    said = churn.communicate(timeout=10.0)[0].strip().splitlines() if churn.poll() is not None \
        else ['still running']
    return dict(done=f'{nodes} rclpy nodes of {lifetime_s:g} s each (own participant, pub/sub/'
                     'service) from another process; sim+planner+controller started in /arm2, '
                     'then stopped',
                notes=f"/arm2 {'waiting' if up else 'not up'} after {up_s:.1f} s; churn: "
                      f'{said[-1] if said else "?"}')


def flood(b: Bench, count: int = 2000) -> dict:
    since = time.time()
    child = b.child('flood', count)
    b.wait_until(lambda: child.poll() is not None, 60.0)
    # The answers settle: none new for 2 s (or the time is up).
    counted, steady_since, deadline = -1, time.monotonic(), time.monotonic() + 3 * b.seconds
    while time.monotonic() < deadline and time.monotonic() - steady_since < 2.0:
        b.wait(0.25)
        now = b.heard.answers(since)
        if now != counted:
            counted, steady_since = now, time.monotonic()
    said = child.communicate(timeout=10.0)[0].strip().splitlines() if child.poll() is not None \
        else ['still running']
    b.call(b.cancel)
    b.wait(b.seconds / 4)
    good = len(flood_goals()) - len(BAD_GOALS)
    return dict(done=f'{count} goal_points published at once from another process '
                     f'({good} good, {len(BAD_GOALS)} bad kinds in turn), publisher depth '
                     f'{count}',
                answers=f'{b.heard.answers(since)}/{count}',
                notes=f'publisher: {said[-1] if said else "?"}; queue cancelled after')


def set_state_names(b: Bench) -> dict:
    shoulder, elbow = 1.2, -0.6
    message = JointState(name=['elbow', 'shoulder'], position=[elbow, shoulder],
                         velocity=[0.0, 0.0])
    since = time.time()
    b.publish(b.set_state_pub, message)
    b.wait(max(1.0, b.seconds / 4))
    limits = [(j.min_angle_rad, j.max_angle_rad) for j in ARM.joints]

    def clipped(q):
        return np.array([np.clip(a, *limit) for a, limit in zip(q, limits)])
    by_name, by_order = clipped((shoulder, elbow)), clipped((elbow, shoulder))
    truth = b.heard.truth_between(since, since + 1.0)[:, 1:]
    if not len(truth):
        verdict = 'no ground truth heard'
    else:
        near_name = np.abs(truth - by_name).max(axis=1).min()
        near_order = np.abs(truth - by_order).max(axis=1).min()
        verdict = ('applied by name' if near_name < 0.05 else
                   f'applied by position: shoulder {by_order[0]:.2f}, elbow {by_order[1]:.2f} '
                   'rad' if near_order < 0.05 else 'not applied as sent')
    return dict(done=f'sim/set_state name [elbow, shoulder] position [{elbow}, {shoulder}]: '
                     f'meant shoulder {shoulder}, elbow {elbow} rad',
                notes=verdict)


def controller_restart(b: Bench) -> dict:
    b.wait(b.seconds / 4)
    killed_s = time.time()
    b.rig.kill('controller')
    b.rig.start('controller')
    started_s = time.time()
    x, y = (float(v) for v in point_of(START_Q))
    while time.time() - started_s < READY_TIMEOUT_S:
        b.send(x, y)
        if b.wait_until(lambda: b.heard.first_answer_s(started_s), 0.25):
            break
    accepted_s = b.heard.first_answer_s(started_s)

    def commands_since_start():        # the new process's: the old one is gone by then
        return [t for t in b.heard.voltage_s if t > started_s]
    b.wait_until(commands_since_start, READY_TIMEOUT_S - (time.time() - started_s))
    b.wait(b.seconds / 4)
    before = [t for t in b.heard.voltage_s if t <= started_s]
    after = commands_since_start()
    silent_from_s = before[-1] if before else killed_s
    if after:
        truth = b.heard.truth_between(after[0], math.inf)
        found = f'{1000 * y_lowest_m(*truth[0, 1:]):.0f} mm' if len(truth) else 'not heard'
        commands = (f'voltage_command silent {after[0] - silent_from_s:.2f} s (a profile '
                    f'ends held; a plain pair: 0 V after {SIM.command_timeout_s:g} s), '
                    f'resumed {after[0] - started_s:.1f} s after the start; lowest point '
                    f'{found} then')
    else:
        commands = f'voltage_command still silent {time.time() - silent_from_s:.1f} s on'
    return dict(done=f'controller SIGKILLed while holding, started again at once; a goal at '
                     f'({x:.2f}, {y:.2f}) every 0.25 s until one is taken',
                ready=f'{accepted_s - started_s:.1f} s' if accepted_s else 'never',
                notes=commands)


ATTACKS = {
    'idle': idle,
    'moves': moves,
    'oversized': oversized,
    'floor_line': floor_line,
    'estop_burst': estop_burst,
    'graph_churn': graph_churn,
    'flood': flood,
    'set_state_names': set_state_names,
    'controller_restart': controller_restart,
    **attacks_live.ATTACKS,             # the second suite: what reaches running nodes
}


# ---------------------------------------------------------------------- running them


def run_attack(b: Bench, name: str) -> dict:
    print(f'== {name}', file=sys.stderr, flush=True)
    try:
        attacks_live.before(b, name)    # the clock's attacks: in simulated time
        b.prepare()
    except Exception as error:
        return dict(attack=name, done='not run', notes=f'the arm could not be prepared: '
                                                       f'{short(str(error), 100)}')
    # Another system on the domain would mix its arm into the readings.
    node = b.rig.probe.node
    counts = {topic: node.count_publishers(topic)
              for topic in ('/sim/ground_truth', '/voltage_command')}
    strangers = [f'{count} publishers of {topic} at the start'
                 for topic, count in counts.items() if count > 1]
    start_s = time.time()
    try:
        row = ATTACKS[name](b)
    except Exception as error:          # the bench carries on; the next attack starts afresh
        row = dict(done='(stopped by an error in the bench)', notes=repr(error))
        b.fresh_next = True
    end_s = time.time()
    p50, p99, worst, count = period_ms(b.heard.voltage_s, start_s, end_s)
    commanding, overall, where = lowest_points_mm(b.heard, start_s, end_s)
    if where:
        print(f'   lowest while commanding {commanding:.0f} mm, {where[0]:.1f} s in, in state '
              f'{where[1]}; {len(b.heard.truth_between(start_s, end_s))} true samples',
              file=sys.stderr, flush=True)
    dead = [n for n, p in b.rig.processes.items() if not p.alive()]
    notes = [row.get('notes', ''), *incidents(b.heard, start_s, end_s)] + \
        ([f'died: {", ".join(dead)}'] if dead else [])
    notes += strangers
    return dict(row, attack=name, commanding=commanding, overall=overall,
                period=f'{p50:.1f} / {p99:.1f} / {worst:.0f}', heard=count,
                notes='; '.join(n for n in notes if n), seconds=end_s - start_s)


def incidents(heard: Listener, start_s: float, end_s: float) -> list:
    """What the controller said of e-stops and of lost joint states (it sends 0 V then)."""
    said = [(kind, text) for t, kind, _, text in heard.events if start_s <= t <= end_s]
    estops = [parse_event(text)[2].split(';')[0].removeprefix('E-STOP: ')
              for kind, text in said if kind in ('estop', 'control_failed')]
    lost = sum(kind == 'sensors_lost' for kind, _ in said)
    out = []
    if estops:
        more = ', ...' if len(set(estops)) > 1 else ''
        out.append(f'{len(estops)} e-stops ({short(estops[0], 30)}{more})')
    if lost:
        out.append(f'joint states lost {lost} times (the last profile held)')
    return out


def table(rows, heading: str) -> str:
    def mm(value):
        return '-' if value is None else f'{value:.0f}'
    lines = [heading, '',
             '| attack | what was done | lowest point while commanding (mm) | lowest point '
             'overall (mm) | voltage_command period p50 / p99 / worst (ms) | answers | time to '
             'ready | notes |', '|---|---|---|---|---|---|---|---|']
    for row in rows:
        lines.append(f"| {row['attack']} | {row['done']} | {mm(row.get('commanding'))} | "
                     f"{mm(row.get('overall'))} | {row.get('period', '-')} | "
                     f"{row.get('answers') or '-'} | {row.get('ready') or '-'} | "
                     f"{row.get('notes', '').replace('|', '/')} |")
    return '\n'.join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--load', action='store_true',
                        help='two busy-loop processes on the machine throughout')
    parser.add_argument('--only', choices=list(ATTACKS), nargs='+',
                        help='run these attacks alone')
    parser.add_argument('--write-docs', action='store_true',
                        help='keep the table in docs/benchmarks/attacks.md')
    parser.add_argument('--seconds', type=float, default=8.0,
                        help='how long an attack watches the arm; other waits scale with it')
    parser.add_argument('--domain', type=int,
                        help='a ROS domain reserved for you (default: a free one, locked as '
                             'the tests lock theirs)')
    args = parser.parse_args()
    names = args.only or list(ATTACKS)
    # Stopped from outside (timeout, kill): still stop the nodes, or they outlive the
    # domain's lock and disturb whoever takes the domain next.
    signal.signal(signal.SIGTERM, _interrupt)
    load_before = os.getloadavg()[0]
    load = busy.start(2, LOAD_BUDGET_S) if args.load else []
    try:
        with ros_domain() if args.domain is None else nullcontext(args.domain) as domain:
            probe = Probe(domain, 'attacks')
            # The DDS threads that stamp each arrival at real-time priority, where allowed,
            # so that the beat measured is the controller's, not this process's wait for a
            # core; the bench's own work stays at normal priority.
            realtime.raise_process(LISTENER_PRIORITY)
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
            heard = Listener(probe.node)
            rig = ArmRig(domain, probe, Path(tempfile.mkdtemp(prefix='arm_attacks_')))
            bench = Bench(rig, heard, args.seconds)
            try:
                began = time.monotonic()
                rig.start_all()
                rig.ready(READY_TIMEOUT_S)
                bring_up_s = time.monotonic() - began
                rows = [run_attack(bench, name) for name in names]
                took_s = time.monotonic() - began
            finally:
                bench.close()
                rig.close()
                probe.close()
    finally:
        busy.stop(load)
    load_said = 'two busy loops added' if args.load else 'no load added'
    text = table(rows, f'Attacks ({load_said}; --seconds {args.seconds:g}): bring-up '
                       f'{bring_up_s:.1f} s, all {took_s:.0f} s; load average '
                       f'{load_before:.1f} before, {os.getloadavg()[0]:.1f} after')
    print(f'\n{text}\n\nnode logs in {rig.log_dir}')
    if args.write_docs:
        command = 'python bench/attacks.py ' + ' '.join(sys.argv[1:])
        print(docs_table.write('attacks', 'Attacks on the running nodes', command, text))


def _interrupt(signum, frame):
    raise KeyboardInterrupt


if __name__ == '__main__':
    main()
