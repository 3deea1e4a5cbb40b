"""The second suite of attacks (issue 39): what reaches the nodes while they run -- live
parameters, other publishers of their inputs and outputs, floods on every input, the clock.
Each is a function of the ``Bench`` (bench/attack_rig.py); bench/attacks.py runs them with
the first suite and measures each the same way. The clock's attacks run the nodes in
simulated time (the sim at 1x real time), the rest as the first suite does.
"""

import math
import time

from attack_rig import Bench, CONTROLLER, PRESETS, short
from ros_harness import NodeProcess
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from arm_control.control.events import parse_event
from arm_control.nodes.common import STATE_STREAM

ROGUE_OFFSET_RAD = math.radians(-20.0)      # the second joint_states: shoulder 20 deg low
ROGUE_RATE_HZ = 50.0
FLOOD_RATE_HZ, FLOOD_S = 500.0, 5.0
SIM_TIME = {'sim': ('-p', 'sim_time_factor:=1.0'), 'planner': ('-p', 'use_sim_time:=true'),
            'controller': ('-p', 'use_sim_time:=true')}


def outcome(result) -> str:
    if result is None:
        return 'unanswered'
    return 'accepted' if result[0] else f'refused ({short(result[1], 60)})'


def moving_to(b: Bench, x: float, y: float) -> bool:
    """A goal sent, and the arm on its way."""
    since = time.time()
    b.send(x, y)
    return b.wait_until(lambda: any(t >= since and s == 'tracking' for t, s in b.heard.states),
                        10.0)


def said_of(b: Bench, since_s: float) -> str:
    """How many of the trust events were heard since ``since_s``, by kind (cause)."""
    counts = {}
    for t, kind, _, text in b.heard.events:
        if t >= since_s and kind in ('untrusted', 'trusted', 'sensors_disagree', 'arm_moved',
                                     'clock_jumped', 'sensors_lost', 'yielded', 'taken_over'):
            key = f'{kind} ({parse_event(text)[1]})' if parse_event(text)[1] else kind
            counts[key] = counts.get(key, 0) + 1
    return ', '.join(f'{n} {k}' for k, n in counts.items()) or 'no trust events'


def alive(b: Bench) -> str:
    dead = [n for n, p in b.rig.processes.items() if not p.alive()]
    b.fresh_next |= bool(dead)
    return 'all nodes alive' if not dead else f'DIED: {", ".join(dead)}'


def live_reserve(b: Bench) -> dict:
    moving = moving_to(b, *PRESETS['floor_pickup'])
    result = b.set_parameters(feedback_voltage_reserve=8.0)[0]
    b.wait(b.seconds / 2)
    if result and result[0]:
        b.set_parameters(feedback_voltage_reserve=CONTROLLER.feedback_voltage_reserve)
    return dict(done='param set feedback_voltage_reserve 8.0 during a move to floor_pickup'
                     + ('' if moving else ' (the move was not seen to start)'),
                notes=f'{outcome(result)}; {alive(b)}')


def live_use_sim_time(b: Bench) -> dict:
    result = b.set_parameters(use_sim_time=True)[0]
    b.wait(b.seconds / 2)
    if result and result[0]:
        b.set_parameters(use_sim_time=False)
        b.fresh_next = True
    return dict(done='param set use_sim_time true on the controller while holding (no /clock)',
                notes=f'{outcome(result)}; {alive(b)}')


def live_gains(b: Bench) -> dict:
    moving = moving_to(b, 1.5, 0.15)
    results = b.set_parameters(shoulder_pid=[1e6, 0.0, 0.0], elbow_pid=[1e6, 0.0, 0.0])
    b.wait(1.5)
    if any(r and r[0] for r in results):
        b.set_parameters(shoulder_pid=list(CONTROLLER.shoulder_pid),
                         elbow_pid=list(CONTROLLER.elbow_pid))
    b.wait(b.seconds / 2)
    return dict(done='shoulder_pid and elbow_pid [1e6, 0, 0] for 1.5 s during a move toward '
                     '(1.5, 0.15)' + ('' if moving else ' (the move was not seen to start)'),
                notes=f'{", ".join(outcome(r) for r in results)}; {alive(b)}')


def second_joint_states(b: Bench) -> dict:
    since = time.time()
    b.send(*PRESETS['floor_pickup'])
    b.wait_until(lambda: b.heard.said(since, 'goal_reached'), 15.0)
    began = time.time()
    node, sent = b.rig.probe.node, 0
    rogue = node.create_publisher(JointState, '/joint_states', STATE_STREAM)
    while time.time() - began < b.seconds:
        if b.heard.truth:
            _, shoulder, elbow = b.heard.truth[-1]
            message = JointState(name=['shoulder', 'elbow'],
                                 position=[shoulder + ROGUE_OFFSET_RAD, elbow],
                                 velocity=[0.0, 0.0])
            message.header.stamp = node.get_clock().now().to_msg()
            rogue.publish(message)
            sent += 1
        b.wait_until(lambda: False, 1.0 / ROGUE_RATE_HZ)
    node.destroy_publisher(rogue)
    b.wait(1.0)
    return dict(done=f'a second publisher of joint_states at {ROGUE_RATE_HZ:g} Hz, the shoulder '
                     f'{math.degrees(ROGUE_OFFSET_RAD):+.0f} deg off, at floor_pickup '
                     f'({sent} sent)', notes=f'{said_of(b, began)}; {alive(b)}')


def second_controller(b: Bench) -> dict:
    began = time.time()
    log_dir = b.rig.log_dir / f'second_controller_{len(b.children)}'
    log_dir.mkdir(parents=True, exist_ok=True)
    twin = NodeProcess('controller', b.rig.domain, (), log_dir)
    try:
        up = b.wait_until(lambda: b.rig.probe.node.count_publishers('/voltage_command') > 1,
                          30.0)
        b.wait(b.seconds)
    finally:
        twin.stop()
    b.wait(1.0)
    b.fresh_next = True                 # the two controllers' states are mixed on arm_state
    return dict(done='a second controller started beside the first, on for '
                     f'{b.seconds:g} s once up' + ('' if up else ' (never seen up)'),
                notes=f'{said_of(b, began)}; {alive(b)}')


def flood_all(b: Bench) -> dict:
    since = time.time()
    child = b.child('flood_all', FLOOD_RATE_HZ, FLOOD_S)
    b.wait_until(lambda: child.poll() is not None, FLOOD_S + 30.0)
    b.wait(2.0)
    said = child.communicate(timeout=10.0)[0].strip().splitlines() if child.poll() is not None \
        else ['still running']
    last = b.rig.controller_diagnostics()
    dropped = ', '.join(f'{k} {v}' for k, v in (last[-1] if last else {}).items()
                        if k.endswith(' dropped'))
    b.call(b.cancel)
    b.wait(b.seconds / 4)
    return dict(done=f'goal_point, goal_preset and driver_velocity each at {FLOOD_RATE_HZ:g} Hz '
                     f'for {FLOOD_S:g} s from another process',
                answers=f'{b.heard.answers(since)} goals answered or counted',
                notes=f'publisher: {said[-1] if said else "?"}; controller: '
                      f'{dropped or "no diagnostics"}; {alive(b)}')


def before(b: Bench, name: str) -> None:
    """Before ``name`` is prepared: the nodes started afresh in simulated time for the
    clock's attacks, in real time for the others."""
    wanted = SIM_TIME if name in ('clock_ahead', 'clock_back') else {}
    if b.rig.node_args != wanted:
        b.rig.node_args = dict(wanted)
        b.fresh_next = True


def clock_jump(b: Bench, jump_s: float) -> dict:
    node = b.rig.probe.node
    publisher = node.create_publisher(Clock, '/clock', 10)
    b.wait_until(lambda: publisher.get_subscription_count() > 1, 10.0)   # planner, controller
    since = time.time()
    moving = moving_to(b, *PRESETS['back_score'])                         # over the top
    clock = b.heard.clock
    if clock is not None:
        rogue = type(clock)(sec=max(0, clock.sec + int(jump_s)), nanosec=clock.nanosec)
        publisher.publish(Clock(clock=rogue))
    b.wait_until(lambda: b.heard.said(since, 'goal_reached'), b.seconds)
    b.wait(b.seconds / 2)
    node.destroy_publisher(publisher)
    reached = bool(b.heard.said(since, 'goal_reached'))
    return dict(done=f'in simulated time (1x), one /clock {jump_s:+g} s during a move to '
                     'back_score' + ('' if moving else ' (the move was not seen to start)'),
                notes=f'{"reached" if reached else "NOT reached"}; {said_of(b, since)}; '
                      f'{alive(b)}')


def clock_ahead(b: Bench) -> dict:
    return clock_jump(b, 100.0)


def clock_back(b: Bench) -> dict:
    return clock_jump(b, -10.0)


ATTACKS = {
    'live_reserve': live_reserve,
    'live_use_sim_time': live_use_sim_time,
    'live_gains': live_gains,
    'second_joint_states': second_joint_states,
    'second_controller': second_controller,
    'flood_all': flood_all,
    'clock_ahead': clock_ahead,
    'clock_back': clock_back,
}
