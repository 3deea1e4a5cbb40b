"""The installed viewer, markers and recorder executables, each beside a real sim."""

import math
import time

from geometry_msgs.msg import PointStamped
from matplotlib import image
import numpy as np
from rclpy.qos import qos_profile_sensor_data
from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import Float64MultiArray, String
from visualization_msgs.msg import MarkerArray

from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.nodes.common import COMMANDS, LATCHED
from arm_control.visual.plots import main as plot_run_main
from arm_control.visual.scene import GOAL_COLOUR, state_colour
from arm_control.visual.scene_view import SceneView


def rgb(colour):
    return np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)])


def colour_near(picture, pixel, colour, radius=2, tolerance=40):
    column, row = pixel
    patch = picture[row - radius:row + radius + 1, column - radius:column + radius + 1, :3]
    return bool(np.any(np.max(np.abs(patch.astype(int) - rgb(colour)), axis=-1) <= tolerance))


def publish_latched_state(probe, state):
    publisher = probe.node.create_publisher(String, '/arm_state', LATCHED)
    publisher.publish(String(data=state))
    return publisher


def test_headless_viewer_draws_the_sim_arm_in_the_state_colour_with_goals(
        launch, probe, tmp_path, arm):
    png = tmp_path / 'viewer.png'
    launch('sim')
    viewer = launch('viewer', '-p', 'headless:=true', '-p', f'png_path:={png}',
                    '-p', 'png_rate_hz:=5.0')
    states = probe.collect(JointState, '/joint_states')
    assert probe.spin_until(lambda: len(states) > 0, 20.0), 'no joint_states from the sim'
    _ = publish_latched_state(probe, 'tracking')
    goals = probe.node.create_publisher(PointStamped, '/goal_point', COMMANDS)
    assert probe.spin_until(lambda: goals.get_subscription_count() > 0, 20.0), \
        'the viewer never subscribed to goal_point'
    goal = PointStamped()
    goal.header.frame_id = 'arm_base'
    goal.point.x, goal.point.y = 1.2, 0.5
    goals.publish(goal)

    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
    reference = SceneView(arm)                  # the same layout: where points land
    goal_pixel = reference.pixel_of(1.2, 0.5)

    def shows_everything():
        """The arm where the sim says it is (it falls at 0 V, then rests), and the goal."""
        if not png.exists():
            return False
        picture = (image.imread(png)[..., :3] * 255).round().astype(np.uint8)
        q = states[-1].position
        elbow, tool = np.array(kinematics.elbow_point(q)), np.array(kinematics.forward(q))
        link_pixels = [reference.pixel_of(*(f * elbow)) for f in (0.3, 0.6)] + \
            [reference.pixel_of(*(elbow + f * (tool - elbow))) for f in (0.3, 0.6)]
        return (all(colour_near(picture, p, state_colour('tracking')) for p in link_pixels)
                and colour_near(picture, (goal_pixel[0] + 4, goal_pixel[1]), GOAL_COLOUR, 1))

    assert probe.spin_until(shows_everything, 30.0), \
        f'{png} never showed the arm in the tracking colour and the goal\n{viewer.output()}'
    assert viewer.alive()


def test_markers_follow_the_sim(launch, probe, arm):
    launch('sim')
    launch('markers')
    received = probe.collect(MarkerArray, '/arm_markers')
    states = probe.collect(JointState, '/joint_states')
    assert probe.spin_until(lambda: len(received) >= 3 and states, 30.0), 'no arm_markers'
    kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)

    def tool_where_the_sim_says():
        """The arm falls at 0 V and comes to rest: then markers and sim agree."""
        links = next(m for m in received[-1].markers if m.ns == 'arm')
        tool = kinematics.forward(states[-1].position)
        return math.dist((links.points[2].x, links.points[2].y), tool) < 0.01

    assert probe.spin_until(tool_where_the_sim_says, 30.0)
    links = next(m for m in received[-1].markers if m.ns == 'arm')
    assert links.header.frame_id == 'arm_base'


def test_recorder_writes_a_bag_that_rosbags_reads(launch, probe, tmp_path):
    """sim + recorder as processes, the rest published here; the bag read by rosbags."""
    bag = tmp_path / 'run'
    launch('sim')
    recorder = launch('recorder', '-p', f'output_dir:={bag}', '-p', 'flush_period_s:=0.5')
    truth = probe.collect(JointState, '/sim/ground_truth')
    assert probe.spin_until(lambda: len(truth) > 0, 20.0)
    _ = publish_latched_state(probe, 'waiting')
    voltage = probe.node.create_publisher(Float64MultiArray, '/voltage_command', COMMANDS)
    battery = probe.node.create_publisher(BatteryState, '/battery_state', COMMANDS)
    currents = probe.node.create_publisher(Float64MultiArray, '/motor_currents',
                                           qos_profile_sensor_data)
    assert probe.spin_until(lambda: voltage.get_subscription_count() >= 2
                            and battery.get_subscription_count() >= 1
                            and currents.get_subscription_count() >= 1, 20.0)
    # Our side sees the recorder's reader; the recorder may not see our writer yet, and a
    # reader drops a volatile sample from a writer it has not matched (24 of 25 once, idle).
    probe.spin_for(1.0)
    start_ns = time.time_ns()
    for k in range(25):
        voltage.publish(Float64MultiArray(data=[1.5, -0.5]))
        battery.publish(BatteryState(voltage=12.0 - 0.01 * k, current=-20.0))
        currents.publish(Float64MultiArray(data=[float(k), 2.0]))
        probe.spin_for(0.02)
    probe.spin_for(1.0)
    assert recorder.stop() == 0, recorder.output()
    end_ns = time.time_ns()

    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        connections = {c.topic: c for c in reader.connections}
        assert {t: c.msgtype for t, c in connections.items()} == {
            '/joint_states': 'sensor_msgs/msg/JointState',
            '/sim/ground_truth': 'sensor_msgs/msg/JointState',
            '/voltage_command': 'std_msgs/msg/Float64MultiArray',
            '/arm_state': 'std_msgs/msg/String',
            '/battery_state': 'sensor_msgs/msg/BatteryState',
            '/motor_currents': 'std_msgs/msg/Float64MultiArray'}
        assert connections['/joint_states'].msgcount > 20
        assert connections['/sim/ground_truth'].msgcount > 20
        assert connections['/voltage_command'].msgcount == 25
        # the electrical topics are recorded best effort (either kind of publisher matches):
        # a sample may be lost on a loaded machine, never invented or reordered
        assert connections['/battery_state'].msgcount >= 20          # the sim's and ours
        assert connections['/motor_currents'].msgcount >= 20
        assert connections['/arm_state'].msgcount == 1
        (latched,) = connections['/arm_state'].ext.offered_qos_profiles
        assert latched.durability == QosDurability.TRANSIENT_LOCAL
        # the type hash the bag names is the one the sim's publisher announces
        (publisher,) = probe.node.get_publishers_info_by_topic('/joint_states')
        assert connections['/joint_states'].digest == str(publisher.topic_type_hash)
        received = {topic: [] for topic in connections}
        times = []
        for connection, time_ns, raw in reader.messages():
            received[connection.topic].append(store.deserialize_cdr(raw, connection.msgtype))
            times.append(time_ns)
    assert start_ns - 30e9 < times[0] and times[-1] < end_ns      # receive times, in ns
    assert times == sorted(times)
    assert [list(m.data) for m in received['/voltage_command']] == [[1.5, -0.5]] * 25
    # The sim publishes these topics too (at rest: no current): the probe's are told apart.
    ours = [m for m in received['/battery_state'] if m.current == -20.0]
    steps = [round(100 * (12.0 - m.voltage)) for m in ours]
    assert len(ours) >= 20 and steps == sorted(set(steps)) and set(steps) <= set(range(25))
    ours = [m for m in received['/motor_currents'] if m.data[1] == 2.0]
    steps = [m.data[0] for m in ours]
    assert len(ours) >= 20 and steps == sorted(set(steps))
    assert set(steps) <= {float(k) for k in range(25)}
    assert received['/arm_state'][0].data == 'waiting'
    assert list(received['/joint_states'][0].name) == ['shoulder', 'elbow']

    assert plot_run_main([str(bag), '-o', str(tmp_path / 'run.png')]) == 0
    assert image.imread(tmp_path / 'run.png').shape[:2] == (760, 1000)
