"""The controller node in process: before it has first looked for the planner, a goal waits
in the queue like one that comes while it looks; once it has yielded the arm to another
controller, it takes no settings; a goal's plan request goes out before what it said; its
start does not load the timing's numba kernels, which only its plan worker uses for goals."""

import os
import signal
import subprocess
import sys
from types import SimpleNamespace

import rclpy
from rclpy.parameter import Parameter

from arm_control.control.events import EventKind as Kind
from arm_control.nodes.common import join_early


def test_a_goal_before_the_first_look_for_the_planner_waits_for_it(controller):
    """Constructed and not yet spun, the node has said once that it waits for the planner,
    and a preset sent then is queued until the planner is up, not planned (it would fail at
    the planner timeout: the service is not there yet)."""
    accepted, _ = controller.command(controller.core.submit_preset, 'mid_score')
    assert accepted
    assert controller.core.goals.waiting_for_planner
    assert [e.kind for e in controller.core.events.history].count(Kind.PLANNER_WAITING) == 1
    assert not controller.core.requests_waiting and controller.plans.outbox == []
    assert os.sched_getscheduler(0) == os.SCHED_OTHER


def test_a_controller_that_yielded_refuses_settings_and_keeps_its_own(controller):
    gains = controller.get_parameter('shoulder_pid').value
    controller.claims.yielding = True
    result = controller.set_parameters([Parameter('shoulder_pid', value=[1.0, 0.0, 0.0])])[0]
    assert not result.successful
    assert controller.get_parameter('shoulder_pid').value == gains
    controller.claims.yielding = False
    result = controller.set_parameters([Parameter('shoulder_pid', value=[1.0, 0.0, 0.0])])[0]
    assert result.successful, result.reason


def test_a_step_s_plan_call_goes_out_before_its_events(controller):
    """The arm waits for the plan, nobody waits for the events: handed on in the same step,
    the planner call goes out before the events (each also a log line), state and queue."""
    import rclpy
    for _ in range(5):                          # what the start said is out of the way
        rclpy.spin_once(controller, timeout_sec=0.05)
    order, request = [], SimpleNamespace(request_id=7)
    controller.plans._call = lambda request, sends: order.append(('request', request))
    publish = controller.events_pub.publish

    def publish_event(message):
        order.append(('event', message.data))
        publish(message)
    controller.events_pub.publish = publish_event
    with controller.lock:                       # as the core's step does, in that order
        controller.core.events.say(0.0, Kind.GOAL_QUEUED, 'info', 'goal queued')
        controller.plans.send([request])
        controller.outputs.trigger()
    for _ in range(4):
        rclpy.spin_once(controller, timeout_sec=0.05)
    assert order[:2] == [('request', request), ('event', 'goal_queued: goal queued')]


START_IN_A_FRESH_PROCESS = '''
import sys
import rclpy
from arm_control.nodes.common import join_early
from arm_control.nodes.controller import ControllerNode
rclpy.init(args=['--ros-args', '-p', 'realtime_priority:=0'], domain_id=int(sys.argv[1]))
node = ControllerNode()
for _ in range(20):
    rclpy.spin_once(node, timeout_sec=0.05)
print(sorted(name for name in sys.modules if name.split('.')[0] == 'numba'))
node.loop.stop()
node.plans.close()
'''


def test_the_controller_starts_without_numba(domain):
    """numba (a third of a second of CPU to import, as much to load the kernels) is the plan
    worker's: the node's own start, a second of its executor included, leaves it out (the
    trajectory server loads the kernels later, or with the first trajectory)."""
    done = subprocess.run([sys.executable, '-c', START_IN_A_FRESH_PROCESS, str(domain)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == '[]', done.stdout


def test_the_node_that_joins_early_is_hidden_and_takes_no_remaps(domain, monkeypatch):
    """The executable's first node makes its DDS participant while the modules load; launched
    as ``-r __node:=controller`` it must not become a second controller (the node counts
    controllers of its name on the graph to find a rival)."""
    monkeypatch.setenv('ROS_DOMAIN_ID', str(domain))
    handler = signal.getsignal(signal.SIGINT)
    joining = join_early(['controller', '--ros-args', '-r', '__node:=controller',
                          '-r', '__ns:=/arm1'], 'controller')
    try:
        assert (joining.get_name(), joining.get_namespace()) == ('_controller_joining', '/')
    finally:
        joining.destroy_node()
        rclpy.try_shutdown()
        signal.signal(signal.SIGINT, handler)
