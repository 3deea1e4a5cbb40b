"""The ROS arm's language end to end: sim, planner and controller as installed processes, and
a client that speaks as MoveIt's controller manager does -- ``rclpy.action`` on
``/controller/follow_joint_trajectory`` -- and one that publishes on
``/controller/joint_trajectory``. Where the arm went is read from the sim's true state."""

import os
import time

from action_msgs.msg import GoalStatus
from arm_rig import DEG, START_Q
from control_msgs.action import FollowJointTrajectory
import numpy as np
import pytest
from rclpy.action import ActionClient, get_action_names_and_types
from ros_harness import stamp_s
from sensor_msgs.msg import JointState
from trajectory_checks import moveit_style
from trajectory_messages import goal_of, trajectory
from trajectory_msgs.msg import JointTrajectory

from arm_control.nodes.common import COMMANDS

ACTION = '/controller/follow_joint_trajectory'
Result = FollowJointTrajectory.Result


@pytest.fixture(scope='module')
def client(rig):
    action = ActionClient(rig.probe.node, FollowJointTrajectory, ACTION)
    assert rig.spin_until(action.server_is_ready, 20.0), 'no follow_joint_trajectory server'
    return action


class Sent:
    """A goal sent as MoveIt sends one: its handle, its feedback, its result."""

    def __init__(self, rig, client, goal):
        self.rig, self.feedback = rig, []
        self.sent_wall_s = time.time()            # on the clock of the sim's stamps
        future = client.send_goal_async(goal, feedback_callback=self.feedback.append)
        assert rig.spin_until(future.done, 10.0), 'the goal was not answered'
        self.handle = future.result()
        assert self.handle.accepted           # refusals come back as results, with the code
        self.result_future = self.handle.get_result_async()

    def result(self, timeout_s=20.0):
        assert self.rig.spin_until(self.result_future.done, timeout_s), 'no result'
        answer = self.result_future.result()
        return answer.status, answer.result


@pytest.fixture
def at_start(rig, client):
    """The arm at rest near its start, taken there by a trajectory if need be; where the
    sensors read it (a client's point 0, as MoveIt takes it from joint_states)."""
    here = np.array(rig.joint_states.last().position)
    if np.max(np.abs(here - START_Q)) > 2 * DEG:
        _, result = Sent(rig, client, goal_of(('shoulder', 'elbow'), [(3.0, START_Q)])).result()
        assert result.error_code == Result.SUCCESSFUL, result.error_string
    assert rig.wait_still(timeout_s=5.0)
    return np.array(rig.joint_states.last().position)


def test_a_moveit_trajectory_is_replayed_and_tracked(rig, client, at_start):
    end = np.array([0.9, -0.5])
    rows = moveit_style(at_start, end, 3.0, count=30)
    since = time.monotonic()
    sent = Sent(rig, client, goal_of(('elbow', 'shoulder'),
                                     [(t, q[::-1], v[::-1], a[::-1]) for t, q, v, a in rows]))
    status, result = sent.result()
    assert (status, result.error_code) == (GoalStatus.STATUS_SUCCEEDED, Result.SUCCESSFUL), \
        result.error_string
    # Feedback as JTC gives it: desired, actual and error, in the arm's joint order.
    assert len(sent.feedback) >= 20
    last = sent.feedback[-1].feedback
    assert list(last.joint_names) == ['shoulder', 'elbow']
    assert np.allclose(np.subtract(last.desired.positions, last.actual.positions),
                       last.error.positions)
    # The true arm against the trajectory asked for: the moment it started is read as the
    # shift (within the first 0.3 s after sending) that fits best.
    samples = rig.truth.messages(since)
    times = np.array([stamp_s(m) for m in samples]) - sent.sent_wall_s
    true_q = np.array([m.position for m in samples])
    wanted = np.array([r[1] for r in rows])
    knots = np.array([r[0] for r in rows])
    inside = (times > 0.0) & (times < 3.5)

    def worst(shift):
        t = np.clip(times[inside] - shift, 0.0, 3.0)
        asked = np.stack([np.interp(t, knots, wanted[:, j]) for j in range(2)], axis=1)
        return np.max(np.abs(true_q[inside] - asked), axis=0)
    errors = min((worst(shift) for shift in np.arange(0.0, 0.3, 0.005)), key=np.max)
    assert np.all(errors < 2.0 * DEG), f'tracking error {np.degrees(errors)} deg'
    assert rig.wait_held(end, tolerance_rad=1.5 * DEG, timeout_s=3.0)


def test_a_trajectory_through_the_floor_is_refused_naming_the_point(rig, client, at_start):
    rows = [(2.0, (0.6, -0.9)), (4.0, (0.2, -0.6)), (6.0, (1.2, -1.0))]
    status, result = Sent(rig, client, goal_of(('shoulder', 'elbow'), rows)).result()
    assert (status, result.error_code) == (GoalStatus.STATUS_ABORTED, Result.INVALID_GOAL)
    assert 'point 1' in result.error_string
    assert rig.wait_held(at_start, timeout_s=2.0)               # it never moved


def test_wrong_joint_names_are_invalid_joints(rig, client, at_start):
    status, result = Sent(rig, client, goal_of(('joint1', 'joint2'),
                                               [(1.0, (1.0, -1.0))])).result()
    assert (status, result.error_code) == (GoalStatus.STATUS_ABORTED, Result.INVALID_JOINTS)


def test_cancel_brakes_and_holds(rig, client, at_start):
    sent = Sent(rig, client, goal_of(('shoulder', 'elbow'),
                                     moveit_style(at_start, (0.9, -0.5), 6.0)))
    rig.spin_for(1.0)
    assert sent.feedback, 'the goal is not under way'
    cancel = sent.handle.cancel_goal_async()
    assert rig.spin_until(cancel.done, 5.0)
    status, _ = sent.result(5.0)
    assert status == GoalStatus.STATUS_CANCELED
    assert rig.wait_still(timeout_s=3.0)
    stopped = rig.true_q()
    assert np.max(np.abs(stopped - (0.9, -0.5))) > 10 * DEG      # short of the end
    assert rig.wait_held(stopped, timeout_s=2.0)


def test_a_new_goal_preempts_the_one_under_way(rig, client, at_start):
    first = Sent(rig, client, goal_of(('shoulder', 'elbow'),
                                      moveit_style(at_start, (0.9, -0.5), 6.0)))
    rig.spin_for(1.0)
    assert first.feedback, 'the first goal is not under way'
    second = Sent(rig, client, goal_of(('shoulder', 'elbow'), [(2.0, (1.3, -1.2), (0, 0))]))
    status, result = first.result(5.0)
    assert (status, result.error_code) == (GoalStatus.STATUS_ABORTED, Result.INVALID_GOAL)
    status, result = second.result(10.0)
    assert (status, result.error_code) == (GoalStatus.STATUS_SUCCEEDED, Result.SUCCESSFUL)
    assert rig.wait_held((1.3, -1.2), tolerance_rad=1.5 * DEG, timeout_s=3.0)


def test_the_topic_moves_the_arm_and_an_empty_message_stops_it(rig, at_start):
    publisher = rig.probe.node.create_publisher(JointTrajectory, '/controller/joint_trajectory',
                                                COMMANDS)
    assert rig.spin_until(lambda: publisher.get_subscription_count() > 0, 10.0)
    publisher.publish(trajectory(('elbow',), [(1.5, (-1.2,))]))          # a partial goal
    assert rig.wait_held((at_start[0], -1.2), tolerance_rad=1.5 * DEG, timeout_s=5.0)
    publisher.publish(trajectory(('shoulder', 'elbow'), [(6.0, (0.9, -0.5))]))
    rig.spin_for(1.5)
    under_way = rig.true_q()
    publisher.publish(JointTrajectory(joint_names=['shoulder', 'elbow']))
    assert rig.wait_still(timeout_s=3.0)
    # Stopped where it was: a 6 s move braked from its slow start, far short of its end.
    assert np.max(np.abs(under_way - (at_start[0], -1.2))) > 1.0 * DEG
    assert np.max(np.abs(rig.true_q() - under_way)) < 5.0 * DEG
    assert np.max(np.abs(rig.true_q() - (0.9, -0.5))) > 5.0 * DEG


def test_without_control_msgs_the_action_is_off_said_once_and_the_topic_works(
        launch, probe, tmp_path):
    hidden = tmp_path / 'hide' / 'control_msgs'
    hidden.mkdir(parents=True)
    (hidden / '__init__.py').write_text("raise ImportError('control_msgs hidden by the test')\n")
    environment = {'PYTHONPATH': f'{hidden.parent}:{os.environ.get("PYTHONPATH", "")}'}
    launch('sim')
    controller = launch('controller', environment=environment)
    truth = probe.collect(JointState, '/sim/ground_truth')
    publisher = probe.node.create_publisher(JointTrajectory, '/controller/joint_trajectory',
                                            COMMANDS)
    assert probe.spin_until(lambda: publisher.get_subscription_count() > 0, 30.0)
    probe.spin_for(3.0)                               # the controller takes the arm
    publisher.publish(trajectory(('shoulder', 'elbow'), [(2.0, (1.3, -1.2))]))

    def there():
        return truth and np.max(np.abs(np.subtract(truth[-1].position, (1.3, -1.2)))) < 2 * DEG
    assert probe.spin_until(there, 10.0), controller.output()
    names = [name for name, _ in get_action_names_and_types(probe.node)]
    assert ACTION not in names
    assert controller.output().count('control_msgs is not installed') == 1
