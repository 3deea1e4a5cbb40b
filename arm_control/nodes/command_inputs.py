"""The controller's commands from people: ``goal_point`` (PointStamped: queued),
``goal_preset`` (String: replaces the queue and the motion, as a driver's button),
``driver_velocity`` (TwistStamped: tool velocity in arm_base), and the services ``~/estop``,
``~/reset``, ``~/cancel`` (Trigger) and ``~/enable`` (SetBool).

Each is admitted by its topic's share of work (``InputGate``), refused while another
controller has the arm, and handed to the core under the node's lock (``command``).
"""

import time

from geometry_msgs.msg import PointStamped, TwistStamped
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger

from arm_control.nodes import messages
from arm_control.nodes.common import guarded, listen, NodePart

# Goals, presets, driver commands kept until taken: answered or counted (``InputGate``).
GOALS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)


class CommandInputs(NodePart):
    """Goals, presets, driver commands and services, on their way to the core."""

    def __init__(self, node):
        self.node = node
        for topic, kind, handler in (
                ('goal_point', PointStamped, self.on_goal_point),
                ('goal_preset', String, self.on_goal_preset),
                ('driver_velocity', TwistStamped, self.on_driver)):
            listen(node, kind, topic, handler, GOALS)
        core = node.core
        for name, call in (('~/estop', core.estop), ('~/reset', core.reset),
                           ('~/cancel', core.cancel)):
            node.create_service(Trigger, name, lambda request, response, call=call:
                                self.on_service(response, call))
        node.create_service(SetBool, '~/enable', lambda request, response: self.on_service(
            response, core.enable, bool(request.data)))

    @guarded
    def on_goal_point(self, msg: PointStamped) -> None:
        if not self.refused('goal_point', msg.header.frame_id, 'frame_id', 'goal'):
            p = msg.point
            self.node.command(self.node.core.submit_goal, p.x, p.y, p.z, msg.header.frame_id)

    @guarded
    def on_goal_preset(self, msg: String) -> None:
        if not self.refused('goal_preset', msg.data, 'preset name', 'preset'):
            self.node.command(self.node.core.submit_preset, msg.data.strip())

    @guarded
    def on_driver(self, msg: TwistStamped) -> None:
        if not self.refused('driver_velocity', msg.header.frame_id, 'frame_id',
                            'driver command'):
            linear = msg.twist.linear
            self.node.command(self.node.core.driver_command, linear.x, linear.y,
                              msg.header.frame_id)

    def refused(self, topic: str, text: str, what: str, whose: str) -> bool:
        """An input beyond its topic's rate is dropped and counted (``InputGate``); text too
        long to be a name is refused before anything formats it."""
        node = self.node
        if not node.gate.admit(topic, time.monotonic()):
            return True
        if node.claims.yielding:
            node.command(node.core.reject, f'{whose} rejected: another controller '
                         'has the arm (this one yielded)', 'yielded')
            return True
        problem = messages.name_problem(text, what)
        if problem:
            node.command(node.core.reject, f'{whose} rejected: {problem}', 'oversized')
        return problem is not None

    @guarded
    def on_service(self, response, call, *args):
        if self.node.claims.yielding:
            response.success, response.message = False, 'another controller has the arm: ' \
                'this one yielded and commands nothing'
            return response
        response.success, response.message = self.node.command(call, *args)
        return response
