"""Bags are rosbag2's Jazzy MCAP layout: read back by an independent reader (rosbags),
decoded from the definitions they carry, and plotted by plot_run."""

import math

from matplotlib import image
import numpy as np
import pytest
from rosbags.interfaces import QosDurability, QosHistory, QosReliability
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_types_from_msg, get_typestore, Stores
import yaml

from arm_control.logs.bag import (BagError, BagWriter, DEFINITION_DELIMITER, load_run,
                                  message_definition, qos_duration)
from arm_control.visual.plots import main as plot_run_main

STORE = get_typestore(Stores.ROS2_JAZZY)          # rosbags' own copies of the Jazzy types
EPOCH_NS = 1_700_000_000_000_000_000
RELIABLE_VOLATILE = {
    'history': 'keep_last', 'depth': 10, 'reliability': 'reliable', 'durability': 'volatile',
    'deadline': qos_duration(0), 'lifespan': qos_duration(0), 'liveliness': 'automatic',
    'liveliness_lease_duration': qos_duration(0), 'avoid_ros_namespace_conventions': False}
LATCHED = dict(RELIABLE_VOLATILE, depth=1, durability='transient_local')

# rosbag2 (jazzy branch) rosbag2_tests/resources/mcap/bag_with_topics_and_service_events/
# metadata.yaml, cut to one topic (and its hash to fit): the fields and their nesting as
# rosbag2 writes them.
# That file is version 8; version 9 (Jazzy's writer, rosbag2_storage/yaml.hpp + qos.cpp)
# writes offered_qos_profiles as a list of maps with policies by name, as in test_qos.cpp.
ROSBAG2_FIXTURE = '''
rosbag2_bagfile_information:
  version: 8
  storage_identifier: mcap
  duration:
    nanoseconds: 70653944
  starting_time:
    nanoseconds_since_epoch: 1699345836270074454
  message_count: 10
  topics_with_message_count:
    - topic_metadata:
        name: /test_topic1
        type: test_msgs/msg/Strings
        serialization_format: cdr
        offered_qos_profiles: ""
        type_description_hash: RIHS01_eee55533636293ac7c94c62432eedb57
      message_count: 1
  compression_format: ""
  compression_mode: ""
  relative_file_paths:
    - bag_with_topics_and_service_events.mcap
  files:
    - path: bag_with_topics_and_service_events.mcap
      starting_time:
        nanoseconds_since_epoch: 1699345836270074454
      duration:
        nanoseconds: 70653944
      message_count: 10
  custom_data: ~
  ros_distro: ""
'''
ROSBAG2_QOS_FIELDS = ['history', 'depth', 'reliability', 'durability', 'deadline', 'lifespan',
                      'liveliness', 'liveliness_lease_duration',
                      'avoid_ros_namespace_conventions']


def cdr(typename: str, **fields) -> bytes:
    """A message serialized by rosbags (not by our code), as DDS carries it."""
    return bytes(STORE.serialize_cdr(STORE.types[typename](**fields), typename))


def joint_state(time_s, position, velocity, names=('shoulder', 'elbow')):
    sec = int(time_s)
    header = STORE.types['std_msgs/msg/Header'](
        stamp=STORE.types['builtin_interfaces/msg/Time'](
            sec=sec, nanosec=round((time_s - sec) * 1e9)), frame_id='')
    return cdr('sensor_msgs/msg/JointState', header=header, name=list(names),
               position=np.array(position, float), velocity=np.array(velocity, float),
               effort=np.zeros(0))


def float_array(values):
    layout = STORE.types['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0)
    return cdr('std_msgs/msg/Float64MultiArray', layout=layout, data=np.array(values, float))


def write_run(path, namespace='', lag_rad=0.1, steps=101):
    """2 s at 50 Hz: the setpoint ramps, the arm lags it by ``lag_rad``, 3 V and -2 V."""
    bag = BagWriter(path, ros_distro='jazzy')
    topics = {name: f'{namespace}/{name}' for name in (
        'joint_states', 'sim/ground_truth', 'controller/setpoint', 'voltage_command',
        'arm_state', 'motor_currents')}
    for name, type_name in (('joint_states', 'sensor_msgs/msg/JointState'),
                            ('sim/ground_truth', 'sensor_msgs/msg/JointState'),
                            ('controller/setpoint', 'sensor_msgs/msg/JointState'),
                            ('voltage_command', 'std_msgs/msg/Float64MultiArray'),
                            ('motor_currents', 'std_msgs/msg/Float64MultiArray')):
        bag.add_topic(topics[name], type_name, [RELIABLE_VOLATILE])
    bag.add_topic(topics['arm_state'], 'std_msgs/msg/String', [LATCHED])
    bag.write(topics['arm_state'], cdr('std_msgs/msg/String', data='tracking'), EPOCH_NS)
    for k in range(steps):
        time_s = 100.0 + 0.02 * k
        receive_ns = EPOCH_NS + k * 20_000_000 + 1000
        setpoint = (0.5 + 0.3 * (time_s - 100.0), -1.0 + 0.2 * (time_s - 100.0))
        true = (setpoint[0] - lag_rad, setpoint[1] + lag_rad)
        # the sensors list the joints the other way round: read by name
        bag.write(topics['joint_states'],
                  joint_state(time_s, true[::-1], (0.2, 0.3), names=('elbow', 'shoulder')),
                  receive_ns)
        bag.write(topics['sim/ground_truth'], joint_state(time_s, true, (0.3, 0.2)),
                  receive_ns)
        bag.write(topics['controller/setpoint'], joint_state(time_s, setpoint, (0.3, 0.2)),
                  receive_ns)
        bag.write(topics['voltage_command'], float_array([3.0, -2.0]), receive_ns + 10,
                  publish_time_ns=receive_ns + 5)
        bag.write(topics['motor_currents'], float_array([40.0, 10.0]), receive_ns + 20)
    bag.close()
    return bag


def keys_tree(value):
    """The nesting of mapping keys, first item standing for a list."""
    if isinstance(value, dict):
        return {key: keys_tree(item) for key, item in value.items()}
    if isinstance(value, list):
        return [keys_tree(value[0])] if value else []
    return None


def test_message_definition_carries_each_nested_type_once_after_the_delimiter():
    """rosbag2's ros2msg form: the type's .msg, then 'MSG: <type>' sections depth first."""
    for type_name, nested in (
            ('sensor_msgs/msg/JointState', ['std_msgs/Header', 'builtin_interfaces/Time']),
            ('std_msgs/msg/Float64MultiArray', ['std_msgs/MultiArrayLayout',
                                                'std_msgs/MultiArrayDimension']),
            ('sensor_msgs/msg/BatteryState', ['std_msgs/Header', 'builtin_interfaces/Time']),
            ('std_msgs/msg/String', [])):
        sections = message_definition(type_name).split(f'\n{DEFINITION_DELIMITER}\n')
        assert [s.split('\n')[0] for s in sections[1:]] == [f'MSG: {n}' for n in nested]
        assert DEFINITION_DELIMITER not in sections[0] and 'MSG: ' not in sections[0]


def test_message_definitions_are_complete_for_an_independent_parser():
    """rosbags builds the types from the definitions alone, and they decode real CDR."""
    store = get_typestore(Stores.EMPTY)
    for type_name in ('sensor_msgs/msg/JointState', 'std_msgs/msg/Float64MultiArray'):
        store.register(get_types_from_msg(message_definition(type_name), type_name))
    decoded = store.deserialize_cdr(joint_state(12.5, (0.25, -1.5), (1.0, 2.0)),
                                    'sensor_msgs/msg/JointState')
    assert list(decoded.position) == [0.25, -1.5] and decoded.header.stamp.nanosec == 5e8
    assert list(store.deserialize_cdr(float_array([1.5, -0.5]),
                                      'std_msgs/msg/Float64MultiArray').data) == [1.5, -0.5]


def test_bag_reads_back_with_rosbags_topic_by_topic(tmp_path):
    write_run(tmp_path / 'run')
    assert sorted(p.name for p in (tmp_path / 'run').iterdir()) == ['metadata.yaml',
                                                                    'run_0.mcap']
    with Reader(tmp_path / 'run') as reader:
        connections = {c.topic: c for c in reader.connections}
        assert {t: (c.msgtype, c.msgcount) for t, c in connections.items()} == {
            '/joint_states': ('sensor_msgs/msg/JointState', 101),
            '/sim/ground_truth': ('sensor_msgs/msg/JointState', 101),
            '/controller/setpoint': ('sensor_msgs/msg/JointState', 101),
            '/voltage_command': ('std_msgs/msg/Float64MultiArray', 101),
            '/motor_currents': ('std_msgs/msg/Float64MultiArray', 101),
            '/arm_state': ('std_msgs/msg/String', 1)}
        assert reader.message_count == 506
        assert reader.start_time == EPOCH_NS
        assert reader.duration == 100 * 20_000_000 + 1020 + 1      # rosbags counts the end
        (latched,) = connections['/arm_state'].ext.offered_qos_profiles
        assert (latched.history, latched.depth, latched.reliability, latched.durability) == (
            QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL)
        assert connections['/joint_states'].digest.startswith('RIHS01_')
        voltages, setpoints = [], []
        for connection, time_ns, raw in reader.messages():
            message = STORE.deserialize_cdr(raw, connection.msgtype)
            if connection.topic == '/voltage_command':
                voltages.append((time_ns, list(message.data)))
            elif connection.topic == '/controller/setpoint':
                setpoints.append(list(message.position))
    assert voltages[0] == (EPOCH_NS + 1010, [3.0, -2.0]) and len(voltages) == 101
    assert setpoints[-1] == pytest.approx([0.5 + 0.3 * 2.0, -1.0 + 0.2 * 2.0])


def test_metadata_yaml_has_rosbag2_jazzy_fields_in_its_nesting(tmp_path):
    written = yaml.safe_load((write_run(tmp_path / 'run').path / 'metadata.yaml').read_text())
    info = written['rosbag2_bagfile_information']
    expected = keys_tree(yaml.safe_load(ROSBAG2_FIXTURE))
    topic = expected['rosbag2_bagfile_information']['topics_with_message_count'][0]
    topic['topic_metadata']['offered_qos_profiles'] = [
        {field: ({'sec': None, 'nsec': None} if field in ('deadline', 'lifespan',
                                                          'liveliness_lease_duration') else None)
         for field in ROSBAG2_QOS_FIELDS}]
    assert keys_tree(written) == expected
    assert list(info) == list(expected['rosbag2_bagfile_information'])    # rosbag2's order
    assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
    assert info['relative_file_paths'] == ['run_0.mcap'] == [f['path'] for f in info['files']]
    assert info['message_count'] == info['files'][0]['message_count'] == sum(
        t['message_count'] for t in info['topics_with_message_count'])
    assert info['ros_distro'] == 'jazzy'


def test_plot_run_reads_a_bag_and_draws_the_run(tmp_path, capsys):
    write_run(tmp_path / 'run', lag_rad=0.1)
    recording, notes = load_run(tmp_path / 'run')
    assert notes == []
    truth, measured = recording.arrays('truth'), recording.arrays('measured')
    assert truth['time_s'][0] == pytest.approx(100.0)              # the header stamps
    assert np.allclose(measured['position'], truth['position'])    # ordered by name
    assert np.allclose(measured['velocity'], [0.3, 0.2])
    assert list(recording.arrays('state')['name']) == ['tracking']
    assert np.all(recording.arrays('voltage')['value'] == [3.0, -2.0])

    assert plot_run_main([str(tmp_path / 'run')]) == 0
    assert image.imread(tmp_path / 'run.png').shape[:2] == (760, 1000)
    assert '2.0 s' in capsys.readouterr().out


def test_load_run_picks_the_arm_of_a_namespace(tmp_path):
    write_run(tmp_path / 'arm1', namespace='/arm1', lag_rad=0.1)
    recording, _ = load_run(tmp_path / 'arm1')
    assert len(recording.arrays('truth')['time_s']) == 101
    recording, _ = load_run(tmp_path / 'arm1' / 'arm1_0.mcap', namespace='arm1')
    assert len(recording.arrays('setpoint')['time_s']) == 101
    recording, _ = load_run(tmp_path / 'arm1', namespace='/arm2')
    assert len(recording) == 0


def test_malformed_messages_are_skipped_and_counted(tmp_path):
    bag = BagWriter(tmp_path / 'bad')
    bag.add_topic('/voltage_command', 'std_msgs/msg/Float64MultiArray')
    bag.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
    for k, values in enumerate(([1.0, 2.0], [1.0], [math.nan, 0.0], [0.5, 0.5, 0.5])):
        bag.write('/voltage_command', float_array(values), EPOCH_NS + k)
    bag.write('/joint_states', joint_state(1.0, (0.1,), (0.0,), names=('shoulder',)), EPOCH_NS)
    bag.close()
    recording, notes = load_run(tmp_path / 'bad')
    assert recording.arrays('voltage')['value'].tolist() == [[1.0, 2.0]]
    assert notes == [
        '1 /joint_states messages skipped: not [shoulder, elbow] as finite numbers',
        '3 /voltage_command messages skipped: not [shoulder, elbow] as finite numbers']


def test_a_bag_is_never_written_over(tmp_path):
    (tmp_path / 'run').mkdir()
    with pytest.raises(BagError, match='already exists'):
        BagWriter(tmp_path / 'run')
    assert list((tmp_path / 'run').iterdir()) == []


def test_plot_run_names_what_it_cannot_read(tmp_path, capsys):
    (tmp_path / 'empty').mkdir()
    assert plot_run_main([str(tmp_path / 'empty')]) == 1
    assert 'neither an MCAP file nor a bag directory' in capsys.readouterr().err
    write_run(tmp_path / 'arm1', namespace='/arm1')
    assert plot_run_main([str(tmp_path / 'arm1'), '--namespace', '/arm2']) == 1
    assert 'holds no joint_states' in capsys.readouterr().err


def test_a_bag_whose_recorder_was_killed_is_read_up_to_its_last_flush(tmp_path):
    """No summary, no footer: what was flushed is still a run."""
    bag = BagWriter(tmp_path / 'killed')
    bag.add_topic('/voltage_command', 'std_msgs/msg/Float64MultiArray')
    for k in range(10):
        bag.write('/voltage_command', float_array([1.0, float(k)]), EPOCH_NS + k)
    bag.flush()
    bag.write('/voltage_command', float_array([1.0, 10.0]), EPOCH_NS + 10)   # not flushed
    cut = (tmp_path / 'killed' / 'killed_0.mcap').read_bytes()
    bag.close()
    (tmp_path / 'killed' / 'killed_0.mcap').write_bytes(cut)
    recording, notes = load_run(tmp_path / 'killed')
    assert recording.arrays('voltage')['value'][:, 1].tolist() == [float(k) for k in range(10)]
    assert notes == [f"{tmp_path / 'killed' / 'killed_0.mcap'} ends early (its recorder never "
                     'closed it): read the 10 messages before the end']
