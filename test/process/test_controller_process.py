"""sim, planner and controller as separate installed processes; goals from a third (the probe).

Every check of where the arm went is made on the sim's true state (``/sim/ground_truth``),
which the controller never sees.
"""

import dataclasses
import math
import os

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TwistStamped
from goal_checks import (assert_each_goal_reached_and_still, goal_publisher, reached, said,
                         tool_track)
from nav_msgs.msg import Path
import numpy as np
import pytest
from ros_harness import lasting
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import SetBool, Trigger

from arm_control import config, parameters, realtime
from arm_control.model.profile import Profile
from arm_control.model.world import ForbiddenSpace
from arm_control.nodes import messages
from arm_control.nodes.common import COMMANDS, controller_sees_planner, LATCHED
from arm_control.plans.cache import preset_pairs
from arm_control.plans.goals import GoalValidator

SETTLE_TIMEOUT_S = 40.0


@pytest.fixture
def probe(probe):
    probe.processes = {}
    return probe


def start_arm(launch, probe, *ros_args):
    """sim, planner and controller; returns (truth, states, events) lists being filled."""
    for name in ('sim', 'planner', 'controller'):
        probe.processes[name] = launch(name, *ros_args)
    truth = probe.collect(JointState, '/sim/ground_truth')
    states = probe.collect(String, '/arm_state', LATCHED)
    events = probe.collect(String, '/controller/events', 50)
    diagnostics = probe.collect(DiagnosticArray, '/diagnostics')

    def controller_ready():          # holding, and its own client has found the planner
        seen = [s for s in map(controller_sees_planner, diagnostics) if s is not None]
        return seen and seen[-1] and states and states[-1].data == 'waiting'
    assert probe.spin_until(controller_ready, 30.0), \
        f'not ready: arm_state {[s.data for s in states]}, diagnostics {diagnostics[-1:]}'
    # The arm fell while the controller was starting: put it back, and watch from there on.
    assert probe.call(Trigger, '/sim/reset', Trigger.Request()).success
    start = np.array(config.load('sim')[1].initial_position)

    def held_at_start():                 # for half a second of true states
        recent = lasting(truth, 0.5)
        return bool(recent) and all(
            np.max(np.abs(np.array(m.position) - start)) < math.radians(2.0) for m in recent)
    assert probe.spin_until(held_at_start, 10.0), 'the controller did not take over the arm'
    truth.clear()
    probe.diagnostics = diagnostics
    return truth, states, events


def worst_periods(diagnostics) -> dict:
    """Each node's worst loop period (ms) per second, as its diagnostics reported them: what
    a failure message needs to tell a stall from a bad plan."""
    worst = {}
    for message in diagnostics:
        for status_ in message.status:
            for value in status_.values:
                if value.key in ('loop period worst (s)', 'worst period (s)') and \
                        value.value != 'nan':
                    worst.setdefault(status_.name, []).append(round(1000 * float(value.value)))
    return worst


def test_goals_reached_in_order_never_below_the_floor(launch, probe, arm):
    truth, states, events = start_arm(launch, probe)
    send = goal_publisher(probe)
    send(math.nan, 1.0)                                   # rejected, with the reason
    send(1.0, 1.0, frame='map')
    assert probe.spin_until(lambda: {c for _, c, _ in said(events, 'goal_rejected')} ==
                            {'not finite', 'wrong frame'}, 10.0)
    assert probe.spin_until(lambda: states[-1].data == 'error', 5.0)

    # Front to back over the top, near full extension close to the floor, a tall reach.
    goals = [(-1.0, 1.0), (1.6, 0.12), (0.4, 1.7), (1.1, 0.9)]
    for goal in goals:
        send(*goal)
    assert probe.spin_until(lambda: len(reached(events)) == len(goals), SETTLE_TIMEOUT_S), \
        [e.data for e in events]
    probe.spin_for(0.5)

    q, qd, xy = tool_track(arm, truth)
    # Within tolerance: 1 deg on each joint moves the tool at most (La + Lb)·1 deg = 3.1 cm.
    assert_each_goal_reached_and_still(goals, xy, qd, 0.031)
    assert np.linalg.norm(xy[-1] - goals[-1]) < 0.031
    lowest = ForbiddenSpace(arm).lowest_point_m(q)
    assert np.min(lowest) >= 0.0, (f'a link went {-np.min(lowest) * 1000:.1f} mm below the '
                                   f'floor; worst periods (ms) per second: '
                                   f'{worst_periods(probe.diagnostics)}')
    assert [s.data for s in states][-1] == 'holding'
    assert 'tracking' in [s.data for s in states]


def diagnostic_value(diagnostics, key, node='controller'):
    """``key``'s value in ``node``'s latest diagnostics, or None."""
    for message in reversed(diagnostics):
        for status_ in message.status:
            if status_.name.endswith(node):
                for value in status_.values:
                    if value.key == key:
                        return value.value
    return None


def test_the_first_goal_from_preset_to_preset_starts_on_its_kept_trajectory(
        launch, probe, arm):
    """While the arm has no goal, the controller asks the planner for every path between
    presets and has each timed finely from rest: the first goal from one preset to another
    then starts on that trajectory, with no quick start to refine."""
    truth, states, events = start_arm(launch, probe)
    pairs = len(preset_pairs(GoalValidator(arm)))

    def kept():
        return int(diagnostic_value(probe.diagnostics, 'trajectories kept') or 0)
    assert probe.spin_until(lambda: kept() >= pairs, 90.0), f'{kept()} of {pairs} kept'
    presets = probe.node.create_publisher(String, '/goal_preset', COMMANDS)
    assert probe.spin_until(lambda: presets.get_subscription_count() > 0, 10.0)
    for count, name in enumerate(('mid_score', 'stow', 'back_score'), start=1):
        presets.publish(String(data=name))
        assert probe.spin_until(lambda: len(reached(events)) == count, 15.0), \
            [e.data[:300] for e in events]
        probe.spin_for(0.3)
    sentences = [sentence for _, _, sentence in reached(events)]
    assert 'kept trajectory' not in sentences[0]            # from where the sim put the arm
    assert all('kept trajectory' in sentence for sentence in sentences[1:]), sentences


def test_services_estop_reset_cancel_enable(launch, probe, arm):
    truth, states, events = start_arm(launch, probe)
    send = goal_publisher(probe)
    send(-1.0, 1.0)
    assert probe.spin_until(lambda: states[-1].data == 'tracking', 10.0)
    response = probe.call(Trigger, '/controller/estop', Trigger.Request())
    assert response.success
    assert probe.spin_until(lambda: states[-1].data == 'estopped' and said(events, 'estop'),
                            5.0)
    send(1.0, 1.0)
    assert probe.spin_until(lambda: any(c == 'estopped' for _, c, _ in said(
        events, 'goal_rejected')), 5.0)
    assert probe.call(Trigger, '/controller/reset', Trigger.Request()).success
    assert probe.spin_until(lambda: states[-1].data == 'waiting', 5.0)
    assert not probe.call(Trigger, '/controller/reset', Trigger.Request()).success
    assert probe.call(SetBool, '/controller/enable', SetBool.Request(data=False)).success
    assert probe.spin_until(lambda: states[-1].data == 'disabled', 5.0)
    assert probe.call(SetBool, '/controller/enable', SetBool.Request(data=True)).success
    assert probe.spin_until(lambda: states[-1].data == 'waiting', 5.0)
    queue = probe.collect(Path, '/controller/goal_queue', LATCHED)
    send(1.1, 0.9)
    send(0.9, 1.5)
    assert probe.spin_until(lambda: states[-1].data == 'tracking', 10.0)
    assert probe.spin_until(lambda: queue and len(queue[-1].poses) == 2, 5.0)
    assert [(p.pose.position.x, p.pose.position.y) for p in queue[-1].poses] == \
        [(1.1, 0.9), (0.9, 1.5)]                            # the current goal first
    response = probe.call(Trigger, '/controller/cancel', Trigger.Request())
    assert response.success and said(events, 'cancelled')
    assert probe.spin_until(lambda: queue and not queue[-1].poses, 5.0)
    assert probe.spin_until(lambda: states[-1].data == 'waiting', 5.0)

    # Malformed input of every kind: said, ignored, the node carries on.
    bad_states = probe.node.create_publisher(JointState, '/joint_states', 10)
    bad_driver = probe.node.create_publisher(TwistStamped, '/driver_velocity', COMMANDS)
    presets = probe.node.create_publisher(String, '/goal_preset', COMMANDS)
    assert probe.spin_until(lambda: bad_states.get_subscription_count() > 0
                            and bad_driver.get_subscription_count() > 0
                            and presets.get_subscription_count() > 0, 10.0)
    bad_states.publish(JointState(name=['wrist'], position=[math.nan]))
    twist = TwistStamped()
    twist.twist.linear.x = math.inf
    bad_driver.publish(twist)
    presets.publish(String(data='moon'))
    send(math.inf, -math.inf, math.nan)
    assert probe.spin_until(lambda: {c for _, c, _ in said(events, 'goal_rejected')} >=
                            {'no such preset', 'not finite'}, 5.0)
    assert probe.processes['controller'].alive()
    assert probe.spin_until(
        lambda: 'ignored joint_states' in probe.processes['controller'].output(), 5.0)

    voltages = probe.collect(Float64MultiArray, '/voltage_command', COMMANDS)
    assert probe.spin_until(lambda: len(voltages) > 10, 5.0)
    holding = messages.command_of(voltages[-1])
    assert isinstance(holding, Profile)                     # command_mode: profile
    assert any(abs(v) > 0.5 for v in holding.setpoints[-1].feedforward_v)   # against gravity
    assert probe.processes['controller'].stop() == 0
    probe.spin_for(0.3)
    # Its last word: a profile ending at rest with its holding volts (the robot holds the
    # arm), the last it computed, not 0 V (issue 39: a hand-over never drops the arm).
    last = messages.command_of(voltages[-1])
    assert isinstance(last, Profile) and last.setpoints[-1].velocity_rad_s == (0.0, 0.0)
    assert any(abs(v) > 0.5 for v in last.setpoints[-1].feedforward_v)
    assert last.start_s >= holding.start_s


@pytest.fixture
def frc_robot_file():
    return parameters.default_parameter_file('frc_robot.yaml')


def test_frc_robot_every_move_planned_with_zero_contact(launch, probe, frc_robot_file):
    """On the competition robot (body, bumpers, intake, extension and height limits) the
    controller plans every move with the planner; the arm never touches forbidden space."""
    frc_arm, _ = config.load('controller', frc_robot_file)
    truth, states, events = start_arm(launch, probe, '--params-file', str(frc_robot_file))
    presets = probe.node.create_publisher(String, '/goal_preset', COMMANDS)
    assert probe.spin_until(lambda: presets.get_subscription_count() > 0, 10.0)
    send = goal_publisher(probe)
    names = ['floor_pickup', 'back_score', 'high_score', 'stow', 'back_score', 'mid_score']
    positions = {name: (x, y) for name, x, y in frc_arm.presets}
    for name in names:
        send(*positions[name])                             # queued, visited in order
    routine = ('goal_queued', 'sensors', 'planner_available')
    assert probe.spin_until(lambda: len(reached(events)) == len(names), 60.0), \
        [e.data[:300] for e in events if not e.data.startswith(routine)]
    probe.spin_for(0.5)                                   # held at the last one
    presets.publish(String(data='shelf_pickup'))          # a button: replaces, goes now
    assert probe.spin_until(lambda: len(reached(events)) == len(names) + 1, 15.0)
    probe.spin_for(0.3)

    q, qd, xy = tool_track(frc_arm, truth)
    assert_each_goal_reached_and_still([positions[n] for n in names + ['shelf_pickup']],
                                       xy, qd, 0.031)
    # The regions themselves (clearance_m is the planner's margin around them).
    bodies = ForbiddenSpace(dataclasses.replace(
        frc_arm, world=dataclasses.replace(frc_arm.world, clearance_m=0.0)))
    contact = ~np.asarray(bodies.is_free(q))
    assert not np.any(contact), (f'{np.sum(contact)} samples in forbidden space, first: '
                                 f'{bodies.why_forbidden(q[contact][0])}')
    assert not any('failed' in e.data for e in events)


def set_parameter(probe, name, value):
    """``ros2 param set /controller name value``: the service's result (successful, reason)."""
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter
    request = SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()])
    return probe.call(SetParameters, '/controller/set_parameters', request).results[0]


def get_parameter(probe, name):
    from rcl_interfaces.srv import GetParameters
    from rclpy.parameter import parameter_value_to_python
    response = probe.call(GetParameters, '/controller/get_parameters',
                          GetParameters.Request(names=[name]))
    return parameter_value_to_python(response.values[0])


def test_live_tuning_takes_good_values_and_refuses_bad_ones(launch, probe):
    """Gains, reserves, tolerances, dwell and presets change at run time; a bad value is
    refused with the reason and the old one kept; the arm's physics stay read-only."""
    truth, states, events = start_arm(launch, probe)
    result = set_parameter(probe, 'shoulder_pid', [70.0, 8.0, 3.5])
    assert result.successful, result.reason
    assert get_parameter(probe, 'shoulder_pid') == [70.0, 8.0, 3.5]
    assert probe.spin_until(lambda: said(events, 'parameters'), 5.0)
    result = set_parameter(probe, 'elbow_pid', [-1.0, 0.0, 0.0])
    assert not result.successful and "'elbow_pid'" in result.reason
    assert get_parameter(probe, 'elbow_pid') == [75.0, 10.0, 3.0]            # kept
    result = set_parameter(probe, 'feedback_voltage_reserve', 13.0)
    assert not result.successful and 'feedback_voltage_reserve' in result.reason
    # Below the battery's volts, but too much for the current limits: refused whole, as at
    # start (it once passed, then killed the controller as it was applied).
    result = set_parameter(probe, 'feedback_voltage_reserve', 8.0)
    assert not result.successful and 'current_limit_a' in result.reason
    result = set_parameter(probe, 'shoulder_pid', [1e6, 0.0, 0.0])      # beyond the bound
    assert not result.successful and "'shoulder_pid'" in result.reason
    result = set_parameter(probe, 'use_sim_time', True)                  # ROS's own
    assert not result.successful and 'use_sim_time' in result.reason
    assert get_parameter(probe, 'use_sim_time') is False
    assert get_parameter(probe, 'shoulder_pid') == [70.0, 8.0, 3.5]      # alive, unchanged
    assert not set_parameter(probe, 'shoulder.mass_kg', 50.0).successful    # read-only
    # A preset moved at run time is where the next press of its button goes.
    assert set_parameter(probe, 'presets.high_score', [0.6, 1.6]).successful
    presets = probe.node.create_publisher(String, '/goal_preset', COMMANDS)
    assert probe.spin_until(lambda: presets.get_subscription_count() > 0, 10.0)
    presets.publish(String(data='high_score'))
    assert probe.spin_until(lambda: len(reached(events)) == 1, SETTLE_TIMEOUT_S)
    probe.spin_for(0.3)
    q, qd, xy = tool_track(config.load('sim')[0], truth)
    assert np.linalg.norm(xy[-1] - (0.6, 1.6)) < 0.031


def test_the_controller_receives_at_its_executor_s_priority(launch, probe):
    """A reading must not wait behind busy processes before the executor takes it: the
    controller's DDS threads (Fast DDS's ``dds.*``, which receive) are SCHED_FIFO at the
    executor's priority, below its loop; where the system refuses, the node says how to
    allow it."""
    from arm_control.nodes.controller import EXECUTOR_PRIORITY
    controller = launch('controller')
    tasks = f'/proc/{controller.process.pid}/task'

    def dds_policies():
        found = set()
        for thread_id in realtime.dds_threads(tasks):
            try:
                found.add((os.sched_getscheduler(thread_id),
                           os.sched_getparam(thread_id).sched_priority))
            except ProcessLookupError:                      # a thread that ended meanwhile
                pass
        return found
    fifo = {(os.SCHED_FIFO, EXECUTOR_PRIORITY)}

    def refused():                  # the loop's priority refused: the executor's is too
        return 'refused' in controller.output()
    assert probe.spin_until(lambda: dds_policies() == fifo or refused(), 30.0), dds_policies()
    if refused():
        assert 'rtprio' in controller.output()              # how to allow it
    else:
        assert dds_policies() == fifo
