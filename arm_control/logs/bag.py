"""Runs recorded as rosbag2 bags in MCAP storage, and read back for plotting. No rclpy here.

A bag is a directory laid out as ``ros2 bag record -s mcap`` leaves it in Jazzy:

    arm_run/
      metadata.yaml      rosbag2_bagfile_information, version 9
      arm_run_0.mcap     profile ros2: a ros2msg schema per type, CDR messages

so that ``ros2 bag info`` and ``ros2 bag play``, Foxglove and PlotJuggler open it. Messages
are stored as they came off the wire (CDR, never re-encoded), stamped as rosbag2 stamps them:
log time = when the recorder received the message, publish time = the publisher's source
time, both in ns since the epoch. The format follows rosbag2's own code (jazzy branch):
``rosbag2_storage/yaml.hpp`` and ``qos.cpp`` (metadata), ``rosbag2_storage_mcap`` (schemas,
channel metadata) and ``LocalMessageDefinitionSource`` (message definitions).
"""

from dataclasses import dataclass
import json
import math
import os
from pathlib import Path
import re
import sys

from mcap.exceptions import McapError
from mcap.reader import make_reader, NonSeekingReader
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, LIBRARY_IDENTIFIER, Writer
from mcap_ros2.decoder import DecoderFactory
import yaml

from arm_control.logs.recording import Recording

ROSBAG2_VERSION = 9                 # rosbag2_storage::BagMetadata::version in Jazzy
NEVER_NS = 2 ** 63 - 1              # rosbag2's starting time of a bag with no message
DEFINITION_DELIMITER = '=' * 80
_TYPE_NAME = re.compile(r'^([a-zA-Z0-9_]+)/(?:msg/)?([a-zA-Z0-9_]+)$')
_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_PRIMITIVE_TYPES = {'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16',
                    'uint16', 'int32', 'uint32', 'int64', 'uint64', 'string'}
# The run's streams: topic (relative to the arm's namespace) -> Recording stream.
JOINT_TOPICS = {'joint_states': 'measured', 'sim/ground_truth': 'truth',
                'controller/setpoint': 'setpoint'}


class BagError(ValueError):
    """A bag that cannot be written where asked, or read as a run of the arm."""


# -- message definitions --------------------------------------------------------------------

def _interface_file(type_name: str, suffix: str) -> Path:
    """share/<package>/msg/<Type><suffix>, found through the ament index, else beside this
    Python (a ROS installed from wheels into a virtual environment)."""
    match = _TYPE_NAME.match(type_name)
    if not match:
        raise BagError(f"'{type_name}' is not a message type name (package/msg/Type)")
    package, name = match.groups()
    try:
        from ament_index_python.packages import get_package_share_directory
        shares = [Path(get_package_share_directory(package))]
    except (ImportError, LookupError, ValueError, OSError):     # OSError: no ament prefix
        shares = []
    shares.append(Path(sys.prefix) / 'share' / package)
    for share in shares:
        path = share / 'msg' / f'{name}{suffix}'
        if path.is_file():
            return path
    raise BagError(f'no definition of {type_name}: {name}{suffix} is in none of '
                   f'{", ".join(str(s / "msg") for s in shares)}')


def message_definition(type_name: str) -> str:
    """The complete ros2msg definition, as rosbag2 stores it: the type's .msg text, then each
    nested type once, depth first, after a line of 80 '=' and a line 'MSG: <type>'."""
    seen = set()

    def definition(name: str, depth: int) -> str:
        if depth == 0:
            raise BagError(f'definition of {type_name} nests too deep')
        text = _interface_file(name, '.msg').read_text()
        package = _TYPE_NAME.match(name).group(1)
        nested = {field if '/' in field else f'{package}/{field}'
                  for field in _FIELD_TYPE.findall(text) if field not in _PRIMITIVE_TYPES}
        for field in sorted(nested):
            if field not in seen:
                seen.add(field)
                text += f'\n{DEFINITION_DELIMITER}\nMSG: {field}\n' + definition(field, depth - 1)
        return text

    return definition(type_name, 50)


def type_hash(type_name: str) -> str:
    """The type's RIHS01 hash, from the type description installed beside its .msg."""
    try:
        hashes = json.loads(_interface_file(type_name, '.json').read_text())['type_hashes']
    except (BagError, OSError, KeyError, ValueError):
        return ''
    full_name = '{}/msg/{}'.format(*_TYPE_NAME.match(type_name).groups())
    return next((h['hash_string'] for h in hashes if h.get('type_name') == full_name), '')


def qos_duration(nanoseconds: int) -> dict:
    """rmw_time_t as rosbag2 writes it: {sec, nsec}."""
    return {'sec': nanoseconds // 1_000_000_000, 'nsec': nanoseconds % 1_000_000_000}


# -- writing --------------------------------------------------------------------------------

@dataclass
class _Topic:
    name: str
    type_name: str
    offered_qos_profiles: list
    type_description_hash: str
    channel_id: int
    message_count: int = 0


class BagWriter:
    """Writes one rosbag2 bag: ``add_topic`` each topic, ``write`` its messages, ``close``.

    Offered QoS profiles are dicts in rosbag2's version-9 form: history, depth, reliability,
    durability, deadline, lifespan, liveliness, liveliness_lease_duration,
    avoid_ros_namespace_conventions (policies by name, e.g. 'keep_last'; durations as
    ``qos_duration``).
    """

    def __init__(self, path, ros_distro: str | None = None):
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f'{self.path} already exists: a bag is never written over; '
                           'name a new directory')
        try:
            self.path.mkdir(parents=True)
        except OSError as error:
            raise BagError(f'cannot create the bag directory {self.path}: {error}') from error
        self.file_name = f'{self.path.name}_0.mcap'
        self.ros_distro = os.environ.get('ROS_DISTRO', '') if ros_distro is None else ros_distro
        self._stream = open(self.path / self.file_name, 'wb')
        # rosbag2's MCAP defaults: no compression, 768 KiB chunks.
        self._mcap = Writer(self._stream, chunk_size=768 * 1024,
                            compression=CompressionType.NONE)
        self._mcap.start(profile='ros2', library=f'arm_control recorder, {LIBRARY_IDENTIFIER}')
        self._schema_ids: dict[str, int] = {}
        self.topics: dict[str, _Topic] = {}
        self.start_ns, self.end_ns = NEVER_NS, None
        self.closed = False

    def add_topic(self, name: str, type_name: str, offered_qos_profiles=()) -> None:
        """A topic such as '/joint_states' of 'sensor_msgs/msg/JointState'; once each."""
        if name in self.topics:
            return
        if type_name not in self._schema_ids:
            self._schema_ids[type_name] = self._mcap.register_schema(
                type_name, SchemaEncoding.ROS2, message_definition(type_name).encode())
        profiles = [dict(p) for p in offered_qos_profiles]
        digest = type_hash(type_name)
        channel_id = self._mcap.register_channel(
            name, MessageEncoding.CDR, self._schema_ids[type_name],
            {'offered_qos_profiles': yaml.safe_dump(profiles, sort_keys=False).rstrip('\n'),
             'topic_type_hash': digest})
        self.topics[name] = _Topic(name, type_name, profiles, digest, channel_id)

    def write(self, topic: str, data: bytes, receive_time_ns: int,
              publish_time_ns: int = 0) -> None:
        """One serialized (CDR) message of a topic added before."""
        entry = self.topics[topic]
        self._mcap.add_message(channel_id=entry.channel_id, log_time=receive_time_ns,
                               publish_time=publish_time_ns or receive_time_ns,
                               sequence=0, data=bytes(data))
        entry.message_count += 1
        self.start_ns = min(self.start_ns, receive_time_ns)
        self.end_ns = receive_time_ns if self.end_ns is None else max(self.end_ns,
                                                                      receive_time_ns)

    @property
    def message_count(self) -> int:
        return sum(t.message_count for t in self.topics.values())

    def metadata(self) -> dict:
        """``rosbag2_bagfile_information`` in the field order rosbag2 Jazzy writes."""
        duration = {'nanoseconds': 0 if self.end_ns is None else self.end_ns - self.start_ns}
        starting_time = {'nanoseconds_since_epoch': self.start_ns}
        return {
            'version': ROSBAG2_VERSION,
            'storage_identifier': 'mcap',
            'duration': duration,
            'starting_time': starting_time,
            'message_count': self.message_count,
            'topics_with_message_count': [
                {'topic_metadata': {'name': t.name, 'type': t.type_name,
                                    'serialization_format': 'cdr',
                                    'offered_qos_profiles': t.offered_qos_profiles,
                                    'type_description_hash': t.type_description_hash},
                 'message_count': t.message_count} for t in self.topics.values()],
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [self.file_name],
            'files': [{'path': self.file_name, 'starting_time': dict(starting_time),
                       'duration': dict(duration), 'message_count': self.message_count}],
            'custom_data': None,
            'ros_distro': self.ros_distro,
        }

    def _write_metadata_yaml(self) -> None:
        """metadata.yaml, written aside and renamed so a reader never sees half of it."""
        text = yaml.safe_dump({'rosbag2_bagfile_information': self.metadata()},
                              sort_keys=False)
        partial = self.path / 'metadata.yaml.part'
        partial.write_text(text)
        os.replace(partial, self.path / 'metadata.yaml')

    def flush(self) -> None:
        """Everything written so far reaches the file (a recorder killed now loses nothing
        before this), and metadata.yaml describes it."""
        self._mcap.flush()
        self._stream.flush()
        self._write_metadata_yaml()

    def close(self) -> None:
        if self.closed:
            return
        # As rosbag2's MCAP storage does on close: the metadata inside the file as well.
        self._mcap.add_metadata('rosbag2', {'serialized_metadata': yaml.safe_dump(
            self.metadata(), sort_keys=False)})
        self._mcap.finish()
        self._stream.close()
        self._write_metadata_yaml()
        self.closed = True


# -- reading a run --------------------------------------------------------------------------

def mcap_files(path) -> list[Path]:
    """The MCAP files of a bag directory (in metadata.yaml's order), or the file itself."""
    path = Path(path)
    if path.is_file():
        return [path]
    metadata = path / 'metadata.yaml'
    if metadata.is_file():
        try:
            info = yaml.safe_load(metadata.read_text())['rosbag2_bagfile_information']
            return [path / name for name in info['relative_file_paths']]
        except (yaml.YAMLError, KeyError, TypeError) as error:
            raise BagError(f'{metadata} is not rosbag2 metadata: {error}') from error
    files = sorted(path.glob('*.mcap'))
    if not files:
        raise BagError(f'{path} is neither an MCAP file nor a bag directory holding one')
    return files


def _joint_pair(names, values) -> list[float] | None:
    """[shoulder, elbow] from a JointState field, by name when the names say, else in order."""
    values = list(values)
    names = list(names)
    if len(names) == len(values) and {'shoulder', 'elbow'} <= set(names):
        values = [values[names.index('shoulder')], values[names.index('elbow')]]
    if len(values) < 2 or not all(math.isfinite(v) for v in values[:2]):
        return None
    return [float(values[0]), float(values[1])]


def _decoded_messages(file: Path) -> tuple[list, bool]:
    """([(topic, log time ns, message)], whether the file was whole). A file whose recorder
    was killed has no summary: it is read from the start up to where it stops."""
    with open(file, 'rb') as stream:
        try:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            return [(channel.topic, message.log_time, decoded)
                    for _, channel, message, decoded in reader.iter_decoded_messages()], True
        except McapError:
            stream.seek(0)
        messages = []
        reader = NonSeekingReader(stream, decoder_factories=[DecoderFactory()])
        try:
            for _, channel, message, decoded in reader.iter_decoded_messages(
                    log_time_order=False):
                messages.append((channel.topic, message.log_time, decoded))
        except McapError:
            pass
        return messages, False


def load_run(path, namespace: str | None = None) -> tuple[Recording, list[str]]:
    """The arm's run in a bag, read through mcap_ros2's decoder: (recording, notes on what
    was skipped). ``namespace`` picks the arm when the bag holds several ('/arm1')."""
    messages, notes = [], []
    for file in mcap_files(path):
        try:
            file_messages, complete = _decoded_messages(file)
        except OSError as error:
            raise BagError(f'cannot read {file}: {error}') from error
        messages += file_messages
        if not complete:
            notes.append(f'{file} ends early (its recorder never closed it): '
                         f'read the {len(file_messages)} messages before the end')
    topics = {topic for topic, _, _ in messages}
    if namespace is None:
        arms = sorted({t[:-len('/joint_states')] for t in topics
                       if t.endswith('/joint_states')})
        if len(arms) > 1:
            raise BagError(f'{path} holds several arms ({", ".join(arms)}): pick one with '
                           'the namespace')
        namespace = arms[0] if arms else ''
    namespace = '/' + namespace.strip('/') if namespace.strip('/') else ''
    streams = {f'{namespace}/{name}': stream for name, stream in JOINT_TOPICS.items()}
    recording, skipped = Recording(), {}
    messages.sort(key=lambda item: item[1])
    for topic, log_time_ns, msg in messages:
        time_s = log_time_ns * 1e-9
        if topic in streams:
            position = _joint_pair(msg.name, msg.position)
            if position is None:
                skipped[topic] = skipped.get(topic, 0) + 1
                continue
            stamp = msg.header.stamp
            if stamp.sec or stamp.nanosec:
                time_s = stamp.sec + 1e-9 * stamp.nanosec
            recording.add_joints(streams[topic], time_s, position,
                                 _joint_pair(msg.name, msg.velocity))
        elif topic == f'{namespace}/voltage_command':
            if len(msg.data) != 2 or not all(math.isfinite(v) for v in msg.data):
                skipped[topic] = skipped.get(topic, 0) + 1
                continue
            recording.add_voltage(time_s, msg.data)
        elif topic == f'{namespace}/arm_state':
            recording.add_state(time_s, msg.data)
    notes += [f'{count} {topic} messages skipped: not [shoulder, elbow] as finite numbers'
              for topic, count in sorted(skipped.items())]
    return recording, notes
