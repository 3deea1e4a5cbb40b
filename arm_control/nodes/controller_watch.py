"""The controller's watch on itself and on the graph, published on ``/diagnostics`` each
second: its loop's periods and compute time, inputs dropped or malformed, the plan worker,
and who else publishes its topics or takes its name (``TrustWatch``)."""

import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from arm_control.control.health import diagnostics, health, loop_values, trust_values
from arm_control.control.trust import GraphCounts
from arm_control.nodes.common import (guarded, loop_statistics, NodePart, output,
                                      PLANNER_AVAILABLE, status)

GRAPH_WATCH_S = 0.5               # how often to count who else publishes its topics
LEVELS = {'ok': DiagnosticStatus.OK, 'warn': DiagnosticStatus.WARN,
          'error': DiagnosticStatus.ERROR}


class ControllerWatch(NodePart):
    """The loop's timings since the last report, and the reports."""

    def __init__(self, node):
        self.node = node
        self.loop_periods_s, self.loop_compute_s, self.last_tick_s = [], [], None
        self.bad_inputs_said = 0
        self.diagnostics_pub = output(node, DiagnosticArray, '/diagnostics', 10)
        node.create_timer(1.0, self.publish_diagnostics)
        node.create_timer(GRAPH_WATCH_S, self.watch_graph)

    def ticked(self, now: float, compute_s: float) -> None:
        """A tick of the loop at ``now`` (control time), its work ``compute_s`` long."""
        if self.last_tick_s is not None:
            self.loop_periods_s.append(now - self.last_tick_s)
        self.last_tick_s = now
        self.loop_compute_s.append(compute_s)

    @guarded
    def watch_graph(self) -> None:
        """Who else publishes what it reads or writes, or takes its name (``TrustWatch``)."""
        node = self.node
        me = (node.get_name(), node.get_namespace())
        counts = GraphCounts(*(node.count_publishers(topic) if topic else 0 for topic in (
            'joint_states', '/clock' if node.loop.simulated() else '', 'voltage_command')),
            node.get_node_names_and_namespaces().count(me))
        with node.lock:
            node.trust.graph(node.core_now_s(), counts)
        node.outputs.trigger()

    @guarded
    def publish_diagnostics(self) -> None:
        node = self.node
        periods, self.loop_periods_s = self.loop_periods_s, []
        compute, self.loop_compute_s = self.loop_compute_s, []
        ages, node.sensors.reading_ages_s = node.sensors.reading_ages_s, []
        stats = loop_statistics(periods, compute)
        malformed, self.bad_inputs_said = node.bad_inputs - self.bad_inputs_said, node.bad_inputs
        problems = [text for bad, text in (
            (not node.plans.worker.alive, 'the plan worker process is gone: goals will fail'),
            (malformed, f'{malformed} malformed messages ignored (the log says which)')) if bad]
        with node.lock:
            node.gate.flush(node.core, node.core_now_s(), time.monotonic())
            values, planner = diagnostics(node.core, node.now_s()), node.core.planner_available
            level, message = health(node.core, stats['worst'], problems,
                                    node.trust.problems.values())
            values.update(trust_values(node.trust))
        values.update(loop_values(stats, ages, node.loop))
        values.update({'bad inputs ignored': node.bad_inputs, PLANNER_AVAILABLE: bool(planner),
                       'trajectories kept': node.plans.worker.kept,
                       **{f'{kind} dropped': n for kind, n in node.gate.dropped.items()},
                       'inputs dropped beyond the work share': node.gate.busy})
        diagnostic = DiagnosticArray()
        diagnostic.header.stamp = node.get_clock().now().to_msg()
        diagnostic.status = [status(node, LEVELS[level], message, values)]
        self.diagnostics_pub.publish(diagnostic)
