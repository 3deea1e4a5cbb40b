"""The identification log: MCAP written and read back, from a bag as ros2 bag would record it."""

import dataclasses

from mcap_ros2.writer import Writer
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

from arm_control.sysid.fit import applied_voltage
from arm_control.sysid.log import Log, LogWriter, read_log, write_log


def _msgdef(type_name: str) -> str:
    """The definition as another writer (rosbags) stores it, for bags not of our making."""
    return get_typestore(Stores.ROS2_JAZZY).generate_msgdef(type_name, ros_version=2)[0]


def a_log(rng) -> Log:
    joint_time = 1_700_000_000.0 + 0.02 * np.arange(100)
    return Log(joint_time_s=joint_time, position_rad=rng.normal(size=(100, 2)),
               velocity_rad_s=rng.normal(size=(100, 2)),
               command_time_s=joint_time + 0.001, voltage_v=rng.uniform(-12, 12, (100, 2)),
               reference_time_s=joint_time + 0.001, reference_rad=rng.normal(size=(100, 2)))


def test_a_log_reads_back_as_written(tmp_path):
    log = a_log(np.random.default_rng(0))
    write_log(tmp_path / 'log.mcap', log)
    back = read_log(tmp_path / 'log.mcap')
    for name in ('joint_time_s', 'position_rad', 'velocity_rad_s', 'command_time_s',
                 'voltage_v', 'reference_time_s', 'reference_rad'):
        # Times to a microsecond: a float holds seconds since 1970 no finer.
        assert np.allclose(getattr(back, name), getattr(log, name), rtol=0, atol=1e-6), name
    assert back.has_reference() and len(back.battery_v) == 0 and not back.notes


def recorded_bag(directory, namespace='', joint_names=('elbow', 'shoulder')):
    """A rosbag2 directory as `ros2 bag record -s mcap` writes it: other topics too, joints
    in any order, no plan; one malformed command."""
    directory.mkdir()
    with open(directory / 'bag_0.mcap', 'wb') as stream:
        writer = Writer(stream)
        joint = writer.register_msgdef('sensor_msgs/JointState',
                                       _msgdef('sensor_msgs/msg/JointState'))
        array = writer.register_msgdef('std_msgs/Float64MultiArray',
                                       _msgdef('std_msgs/msg/Float64MultiArray'))
        text = writer.register_msgdef('std_msgs/String', _msgdef('std_msgs/msg/String'))
        for k in range(50):
            t = 100 + 0.02 * k
            stamp = {'sec': int(t), 'nanosec': int(round((t % 1) * 1e9))}
            position = {'shoulder': 1.0 + 0.01 * k, 'elbow': -0.5}
            writer.write_message(f'{namespace}/joint_states', joint, {
                'header': {'stamp': stamp, 'frame_id': ''}, 'name': list(joint_names),
                'position': [position[n] for n in joint_names], 'velocity': [0.0, 0.0],
                'effort': []}, log_time=int(t * 1e9) + 2_000_000)
            data = [1.0, 2.0] if k != 7 else [float('nan'), 2.0]
            writer.write_message(f'{namespace}/voltage_command', array,
                                 {'layout': {'dim': [], 'data_offset': 0}, 'data': data},
                                 log_time=int(t * 1e9) + 3_000_000)
            writer.write_message('/arm_state', text, {'data': 'moving'},
                                 log_time=int(t * 1e9))
        writer.finish()
    return directory


def test_a_recorded_bag_directory_is_read_by_topic_name(tmp_path):
    log = read_log(recorded_bag(tmp_path / 'bag', namespace='/robot'))
    assert len(log.joint_time_s) == 50 and len(log.command_time_s) == 49
    assert np.allclose(log.position_rad[:, 0], 1.0 + 0.01 * np.arange(50))    # by name
    assert np.allclose(log.position_rad[:, 1], -0.5)
    assert log.joint_time_s[0] == pytest.approx(100.0)          # the sensor's stamp
    assert log.command_time_s[0] == pytest.approx(100.003)      # when it was logged
    assert not log.has_reference()
    assert log.notes == ['1 voltage_command messages skipped: malformed or not '
                         '[shoulder, elbow]']


def test_a_bag_without_commands_says_what_is_missing(tmp_path):
    directory = tmp_path / 'empty'
    directory.mkdir()
    with open(directory / 'only_text.mcap', 'wb') as stream:
        writer = Writer(stream)
        text = writer.register_msgdef('std_msgs/String', _msgdef('std_msgs/msg/String'))
        writer.write_message('/arm_state', text, {'data': 'idle'}, log_time=1)
        writer.finish()
    with pytest.raises(ValueError, match='0 joint_states and 0 voltage_command'):
        read_log(directory)
    with pytest.raises(ValueError, match='no bag at'):
        read_log(tmp_path / 'missing.mcap')


def test_the_nodes_messages_are_logged_as_they_are(tmp_path):
    """The node writes rclpy's JointState and BatteryState objects directly."""
    from sensor_msgs.msg import BatteryState, JointState
    with LogWriter(tmp_path / 'log.mcap') as writer:
        for k in range(10):
            t = 50.0 + 0.02 * k
            state = JointState(name=['elbow', 'shoulder'], position=[-1.0, 0.1 * k],
                               velocity=[0.0, 0.5])
            state.header.stamp.sec, state.header.stamp.nanosec = 50, 20_000_000 * k
            writer.joint_state(t, state)
            writer.voltage(t, [6.0, -3.0])
            battery = BatteryState(voltage=11.0 - 0.1 * k, current=-30.0)
            battery.header.stamp = state.header.stamp
            writer.battery(t, battery)
    log = read_log(tmp_path / 'log.mcap')
    assert np.allclose(log.position_rad, [[0.1 * k, -1.0] for k in range(10)])
    assert np.allclose(log.velocity_rad_s, [[0.5, 0.0]] * 10)
    assert np.allclose(log.battery_v, 11.0 - 0.1 * np.arange(10))


def test_the_voltage_the_arm_got_is_the_command_held_and_at_most_the_battery():
    """Zero-order hold from ``lag`` after sending, averaged over each interval; a sagging
    battery caps it."""
    log = Log(joint_time_s=np.zeros(0), position_rad=np.zeros((0, 2)),
              velocity_rad_s=np.zeros((0, 2)), command_time_s=np.array([0.0, 0.02, 0.04]),
              voltage_v=np.array([[2.0, 4.0], [6.0, -12.0], [0.0, 0.0]]))
    start, end = np.array([0.0, 0.01, 0.02]), np.array([0.02, 0.03, 0.04])
    mean, inside = applied_voltage(log, start, end, 0.0)
    assert np.allclose(mean, [[2.0, 4.0], [4.0, -4.0], [6.0, -12.0]])
    mean, _ = applied_voltage(log, start, end, 0.01)            # 10 ms later
    assert np.allclose(mean[1], [2.0, 4.0]) and np.all(inside)
    sagging = dataclasses.replace(log, battery_time_s=np.array([0.0, 0.04]),
                                  battery_v=np.array([9.0, 9.0]))
    mean, _ = applied_voltage(sagging, start, end, 0.0)
    assert np.allclose(mean[2], [6.0, -9.0])
