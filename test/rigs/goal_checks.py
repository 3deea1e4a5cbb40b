"""Goals sent from a probe, and what the controller's events and the sim's truth say of them."""

from geometry_msgs.msg import PointStamped
import numpy as np

from arm_control.control.events import parse_event
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.nodes.common import COMMANDS


def goal_publisher(probe):
    publisher = probe.node.create_publisher(PointStamped, '/goal_point', COMMANDS)
    assert probe.spin_until(lambda: publisher.get_subscription_count() > 0, 10.0)

    def send(x, y, z=0.0, frame='arm_base'):
        message = PointStamped()
        message.header.frame_id = frame
        message.point.x, message.point.y, message.point.z = float(x), float(y), float(z)
        publisher.publish(message)
    return send


def said(events, kind):
    """The (kind, cause, sentence) of the events of ``kind`` heard."""
    return [event for event in map(parse_event, (e.data for e in events)) if event[0] == kind]


def reached(events):
    return said(events, 'goal_reached')


def tool_track(arm, truth):
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    q = np.array([m.position for m in truth])
    qd = np.array([m.velocity for m in truth])
    xy = np.array([kinematics.forward(row) for row in q])
    return q, qd, xy


def assert_each_goal_reached_and_still(goals, xy, qd, tolerance_m):
    """For each goal, some true sample put the tool within tolerance with the arm still."""
    still = np.all(np.abs(qd) < 0.1, axis=1)
    for goal in goals:
        closest = np.min(np.where(still, np.linalg.norm(xy - np.array(goal), axis=1), np.inf))
        assert closest < tolerance_m, f'goal {goal}: closest still approach {closest:.4f} m'
