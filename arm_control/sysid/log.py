"""The identification log: every sample, as a rosbag2-style MCAP file, and back.

Written with ``mcap_ros2`` in the ``ros2`` profile (CDR messages, ``ros2msg`` schemas, the
definitions rosbag2 would store), so ``ros2 bag info``/``play``, Foxglove and PlotJuggler
open it too. Topics: ``/joint_states`` (sensor_msgs/JointState, stamped by the sensor),
``/voltage_command`` (std_msgs/Float64MultiArray, logged when sent), ``/sysid/reference``
(sensor_msgs/JointState: the planned position and velocity the command was computed for;
the fit's instruments) and, when the robot publishes it, ``/battery_state``
(sensor_msgs/BatteryState).

``read_log`` takes any such file or a rosbag2 directory of them (``ros2 bag record -s mcap
/joint_states /voltage_command``): it finds the topics by name, also under a namespace.
"""

from dataclasses import dataclass, field
import math
from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer
import numpy as np

from arm_control.config import JOINT_NAMES
from arm_control.logs.bag import message_definition

JOINT_STATES = 'joint_states'
VOLTAGE_COMMAND = 'voltage_command'
BATTERY_STATE = 'battery_state'
REFERENCE = 'reference'
# kind: (the topic written, its type); a bag's topics are found by their last name.
_TOPICS = {JOINT_STATES: ('/joint_states', 'sensor_msgs/msg/JointState'),
           VOLTAGE_COMMAND: ('/voltage_command', 'std_msgs/msg/Float64MultiArray'),
           BATTERY_STATE: ('/battery_state', 'sensor_msgs/msg/BatteryState'),
           REFERENCE: ('/sysid/reference', 'sensor_msgs/msg/JointState')}


@dataclass
class Log:
    """The samples of one run, times in seconds on the log's clock."""

    joint_time_s: np.ndarray                 # (N,)
    position_rad: np.ndarray                 # (N, 2) [shoulder, elbow]
    velocity_rad_s: np.ndarray               # (N, 2), NaN where the message had none
    command_time_s: np.ndarray               # (M,)
    voltage_v: np.ndarray                    # (M, 2) as commanded
    battery_time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    battery_v: np.ndarray = field(default_factory=lambda: np.zeros(0))
    reference_time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    reference_rad: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    notes: list = field(default_factory=list)   # what the reader skipped, and why

    def has_reference(self) -> bool:
        """Whether the planned motion was logged over the whole of the joint samples."""
        return (len(self.reference_time_s) > 1 and len(self.joint_time_s) > 1
                and self.reference_time_s[0] <= self.joint_time_s[0] + 0.1
                and self.reference_time_s[-1] >= self.joint_time_s[-1] - 0.1)

    def reference_at(self, time_s) -> np.ndarray:
        """The planned positions at ``time_s`` (linear between samples), (N, 2)."""
        return np.column_stack([np.interp(time_s, self.reference_time_s,
                                          self.reference_rad[:, j]) for j in range(2)])

    @property
    def duration_s(self) -> float:
        return float(self.joint_time_s[-1] - self.joint_time_s[0]) if len(self.joint_time_s) \
            else 0.0


class Samples:
    """What the node has logged so far, kept in memory for the stage-1 fit."""

    def __init__(self):
        self.joints, self.commands = [], []

    def joint(self, time_s, position, velocity) -> None:
        self.joints.append((time_s, np.array(position, float), np.array(velocity, float)))

    def command(self, time_s, voltage, reference_rad) -> None:
        self.commands.append((time_s, np.array(voltage, float), np.array(reference_rad, float)))

    def log(self) -> Log:
        joints, commands = self.joints, self.commands
        times = np.array([c[0] for c in commands])
        return Log(joint_time_s=np.array([s[0] for s in joints]),
                   position_rad=np.array([s[1] for s in joints]),
                   velocity_rad_s=np.array([s[2] for s in joints]),
                   command_time_s=times, voltage_v=np.array([c[1] for c in commands]),
                   reference_time_s=times.copy(),
                   reference_rad=np.array([c[2] for c in commands]))


def _stamp(time_s: float) -> dict:
    nanoseconds = int(round(time_s * 1e9))
    return {'sec': nanoseconds // 1_000_000_000, 'nanosec': nanoseconds % 1_000_000_000}


def _joint_state(time_s, position, velocity, effort=()) -> dict:
    return {'header': {'stamp': _stamp(time_s), 'frame_id': ''}, 'name': list(JOINT_NAMES),
            'position': [float(v) for v in position], 'velocity': [float(v) for v in velocity],
            'effort': [float(v) for v in effort]}


class LogWriter:
    """Appends samples to an MCAP file; ``close`` (or leaving a ``with``) finishes it."""

    def __init__(self, path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, 'wb')
        self._writer = Writer(self._file)
        self._schemas = {}
        for kind, (_, name) in _TOPICS.items():
            short = name.replace('/msg/', '/')
            self._schemas[kind] = self._writer.register_msgdef(short, message_definition(short))
        self._sequence = 0

    def _write(self, kind, message, time_s):
        self._sequence += 1
        nanoseconds = int(round(time_s * 1e9))
        self._writer.write_message(_TOPICS[kind][0], self._schemas[kind], message,
                                   log_time=nanoseconds, publish_time=nanoseconds,
                                   sequence=self._sequence)

    def joint_state(self, time_s: float, message=None, *, position=(), velocity=(),
                    effort=()) -> None:
        """A JointState (a message object, or built from the arrays, stamped ``time_s``)."""
        self._write(JOINT_STATES, message or _joint_state(time_s, position, velocity, effort),
                    time_s)

    def reference(self, time_s: float, position, velocity) -> None:
        """The planned position and velocity a command was computed for."""
        self._write(REFERENCE, _joint_state(time_s, position, velocity), time_s)

    def voltage(self, time_s: float, voltage) -> None:
        self._write(VOLTAGE_COMMAND, {'layout': {'dim': [], 'data_offset': 0},
                                      'data': [float(v) for v in voltage]}, time_s)

    def battery(self, time_s: float, message) -> None:
        self._write(BATTERY_STATE, message, time_s)

    def close(self) -> None:
        if not self._file.closed:
            self._writer.finish()
            self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def write_log(path, log: Log) -> None:
    """A whole ``Log`` to an MCAP file (what the node writes sample by sample)."""
    with LogWriter(path) as writer:
        for t, q, v in zip(log.joint_time_s, log.position_rad, log.velocity_rad_s):
            writer.joint_state(t, position=q, velocity=v)
        for t, volts in zip(log.command_time_s, log.voltage_v):
            writer.voltage(t, volts)
        for t, q in zip(log.reference_time_s, log.reference_rad):
            writer.reference(t, q, [])


def _files(path) -> list[Path]:
    path = Path(path)
    if path.is_dir():
        files = sorted(path.glob('*.mcap'))
        if not files:
            raise ValueError(f'{path} holds no .mcap file')
        return files
    if not path.is_file():
        raise ValueError(f'no bag at {path}')
    return [path]


def _pick_topic(topics, wanted):
    """The topic named ``wanted``, or the one topic ending in /``wanted``."""
    if '/' + wanted in topics:
        return '/' + wanted
    matches = sorted(t for t in topics if t.rstrip('/').split('/')[-1] == wanted)
    if len(matches) > 1:
        raise ValueError(f'several {wanted} topics in the bag ({", ".join(matches)}): '
                         'keep one')
    return matches[0] if matches else None


def _time_s(message, log_time_ns) -> float:
    header = getattr(message, 'header', None)
    if header is not None and (header.stamp.sec or header.stamp.nanosec):
        return header.stamp.sec + 1e-9 * header.stamp.nanosec
    return log_time_ns * 1e-9


def read_log(path) -> Log:
    """Joint states, voltage commands, the plan and battery voltage from a bag (a file or a
    rosbag2 directory)."""
    samples = {kind: [] for kind in _TOPICS}
    skipped = {kind: 0 for kind in _TOPICS}
    notes = []
    for file in _files(path):
        with open(file, 'rb') as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            summary = reader.get_summary()
            if summary is None:
                raise ValueError(f'{file} has no summary: was it closed properly?')
            types = {c.topic: summary.schemas[c.schema_id].name
                     for c in summary.channels.values() if c.schema_id in summary.schemas}
            chosen = {}
            for kind, (_, type_name) in _TOPICS.items():
                topic = _pick_topic(types, kind.split('/')[-1])
                if topic is None:
                    continue
                if types[topic].replace('/msg/', '/') != type_name.replace('/msg/', '/'):
                    notes.append(f'{topic} is a {types[topic]}, not a {type_name}: not read')
                    continue
                chosen[topic] = kind
            if not chosen:
                continue
            for _, channel, record, message in reader.iter_decoded_messages(
                    topics=list(chosen)):
                kind = chosen[channel.topic]
                sample = _sample(kind, message, record.log_time)
                if sample is None:
                    skipped[kind] += 1
                else:
                    samples[kind].append(sample)
    for kind, count in skipped.items():
        if count:
            notes.append(f'{count} {kind} messages skipped: malformed or not [shoulder, elbow]')
    joints, commands = samples[JOINT_STATES], samples[VOLTAGE_COMMAND]
    if len(joints) < 2 or len(commands) < 2:
        raise ValueError(f'{path}: {len(joints)} joint_states and {len(commands)} '
                         'voltage_command messages; a fit needs both topics')
    for kind in samples:
        samples[kind].sort(key=lambda sample: sample[0])
    battery, reference = samples[BATTERY_STATE], samples[REFERENCE]
    return Log(
        joint_time_s=np.array([s[0] for s in joints]),
        position_rad=np.array([s[1] for s in joints]),
        velocity_rad_s=np.array([s[2] for s in joints]),
        command_time_s=np.array([s[0] for s in commands]),
        voltage_v=np.array([s[1] for s in commands]),
        battery_time_s=np.array([s[0] for s in battery]),
        battery_v=np.array([s[1] for s in battery]),
        reference_time_s=np.array([s[0] for s in reference]),
        reference_rad=np.array([s[1] for s in reference]).reshape(-1, 2),
        notes=notes)


def _sample(kind, message, log_time_ns):
    """(time, values...) from one message, or None when it cannot be used."""
    if kind in (JOINT_STATES, REFERENCE):
        sample = _joint_sample(message)
        return None if sample is None else (_time_s(message, log_time_ns), *sample)
    if kind == VOLTAGE_COMMAND:
        data = list(message.data)
        if len(data) != 2 or not all(math.isfinite(v) for v in data):
            return None
        return log_time_ns * 1e-9, data
    if math.isfinite(message.voltage) and message.voltage > 0.0:
        return _time_s(message, log_time_ns), message.voltage
    return None


def _joint_sample(message):
    """([shoulder, elbow] positions, velocities) from a JointState, or None if unusable."""
    names, position, velocity = list(message.name), list(message.position), \
        list(message.velocity)
    if names and all(n in names for n in JOINT_NAMES):
        index = [names.index(n) for n in JOINT_NAMES]
    elif not names and len(position) == 2:
        index = [0, 1]
    else:
        return None
    if len(position) != len(names or position) or max(index) >= len(position):
        return None
    q = [position[i] for i in index]
    v = ([velocity[i] for i in index] if len(velocity) == len(position)
         else [math.nan, math.nan])
    if not all(math.isfinite(x) for x in q):
        return None
    return q, v
