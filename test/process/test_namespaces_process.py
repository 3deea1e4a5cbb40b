"""Two arms side by side on one ROS domain, each pushed into its own namespace, as the launch
file's ``namespace`` argument does: each reaches its own goal and hears only its own
commands. (``/diagnostics`` is absolute, so both arms share it: that is expected.)"""

import math

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.nodes.common import COMMANDS, controller_sees_planner, LATCHED

ARMS = {'/arm1': (1.1, 0.9), '/arm2': (0.5, 1.3)}      # namespace: its goal in arm_base (m)
# Six nodes share the machine here: gentle moves, and the tracking-error e-stop given time,
# so that a loop held up by the load does not stop the arms. The wiring is under test.
GENTLE = ('-p', 'max_velocity_rad_s:=[1.5, 1.5]', '-p', 'max_acceleration_rad_s2:=[6.0, 6.0]',
          '-p', 'tracking_error_time_s:=3.0')


def test_two_arms_in_namespaces_reach_their_own_goals(launch, probe, arm):
    controllers = {}
    for namespace in ARMS:
        launch('sim', '-r', f'__ns:={namespace}')
        launch('planner', '-r', f'__ns:={namespace}')
        controllers[namespace] = launch('controller', '-r', f'__ns:={namespace}', *GENTLE)
    truth = {ns: probe.collect(JointState, f'{ns}/sim/ground_truth') for ns in ARMS}
    states = {ns: probe.collect(String, f'{ns}/arm_state', LATCHED) for ns in ARMS}
    planner_seen = {}

    def on_diagnostics(message: DiagnosticArray):
        for status in message.status:
            seen = controller_sees_planner(DiagnosticArray(status=[status]))
            if seen is not None:
                planner_seen[status.name] = seen
    probe.node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
    assert probe.spin_until(lambda: all(planner_seen.get(f'{ns}/controller') for ns in ARMS)
                            and all(truth.values()), 60.0), \
        f'controllers not ready: planner seen {planner_seen}'

    # Each namespace's command topics join its own controller to its own sim, and no other.
    # (An endpoint's node may be named '_NODE_NAMESPACE_UNKNOWN_' until discovery catches up.)
    def namespaces_at(topic):
        ends = (probe.node.get_publishers_info_by_topic(topic)
                + probe.node.get_subscriptions_info_by_topic(topic))
        return {(e.node_namespace, e.node_name) for e in ends}

    for namespace in ARMS:
        for topic, nodes in (('voltage_command', {'controller', 'sim'}),
                             ('goal_point', {'controller'})):
            expected = {(namespace, node) for node in nodes}
            assert probe.spin_until(lambda: namespaces_at(f'{namespace}/{topic}') == expected,
                                    10.0), (topic, namespaces_at(f'{namespace}/{topic}'))

    publishers = {ns: probe.node.create_publisher(PointStamped, f'{ns}/goal_point', COMMANDS)
                  for ns in ARMS}
    assert probe.spin_until(
        lambda: all(p.get_subscription_count() >= 1 for p in publishers.values()), 20.0)
    for namespace, (x, y) in ARMS.items():
        goal = PointStamped()
        goal.header.frame_id = 'arm_base'
        goal.point.x, goal.point.y = x, y
        publishers[namespace].publish(goal)

    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)

    def tool_at_goal(namespace):
        x, y = ARMS[namespace]
        return (states[namespace] and states[namespace][-1].data == 'holding'
                and math.dist(kinematics.forward(truth[namespace][-1].position), (x, y)) < 0.01)

    assert probe.spin_until(lambda: all(tool_at_goal(ns) for ns in ARMS), 40.0), '\n'.join(
        f'{ns}: {states[ns][-1].data if states[ns] else None}, tool at '
        f'{kinematics.forward(truth[ns][-1].position)}\n{controllers[ns].output()[-1500:]}'
        for ns in ARMS)
    # Nothing was published on the names without a namespace.
    assert probe.node.get_publishers_info_by_topic('/voltage_command') == []
    assert probe.node.get_publishers_info_by_topic('/joint_states') == []
