"""ROS messages to plain values and back: the one place every node shell parses and builds.

Parsing is strict and never raises: a malformed message gives None (or a reason), which the
node counts and reports. Text from outside is bounded here, before anything formats it.
"""

import math
from typing import Optional

from geometry_msgs.msg import PoseStamped, Quaternion
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header, MultiArrayDimension

from arm_control.config import FRAME_ID, JOINT_NAMES
from arm_control.model.profile import decode_command, encode, Profile
from arm_control.text import quote

# Names (a preset, a frame) longer than this are refused before they are logged or echoed.
MAX_NAME_CHARS = 64


def joint_pair(msg: JointState, field: str = 'position') -> Optional[list[float]]:
    """(shoulder, elbow) of ``field``, by joint name -- or in order when the message names
    no joints; None when the names are not [shoulder, elbow] in some order, or the lengths
    do not match."""
    values, names = list(getattr(msg, field)), list(msg.name)
    if names:
        if len(names) != len(values) or sorted(names) != sorted(JOINT_NAMES):
            return None
        return [float(values[names.index(name)]) for name in JOINT_NAMES]
    return [float(v) for v in values] if len(values) == 2 else None


def joint_readings(msg: JointState, max_angle_rad: float, top_speed_rad_s: float):
    """(positions, velocities) of [shoulder, elbow] (NaN velocities when none are given), or
    a str saying why the message cannot be a reading: positions not finite or beyond
    ``max_angle_rad``, velocities beyond ``top_speed_rad_s``."""
    position = joint_pair(msg, 'position')
    velocity = joint_pair(msg, 'velocity') or [math.nan, math.nan]
    if position is None or not within(position, max_angle_rad) or \
            not within([v for v in velocity if not math.isnan(v)], top_speed_rad_s):
        return (f'expected finite positions of [shoulder, elbow] within '
                f'{max_angle_rad:.1f} rad and velocities, if any, within '
                f'{top_speed_rad_s:.0f} rad/s; got {len(msg.name)} names, '
                f'{len(msg.position)} positions, {len(msg.velocity)} velocities')
    return position, velocity


def within(values, bound: float) -> bool:
    """Every value finite and within ±bound."""
    return all(math.isfinite(v) and abs(v) <= bound for v in values)


def finite(values) -> bool:
    return all(isinstance(v, (int, float)) and math.isfinite(v) for v in values)


def stamp_s(header: Header) -> float:
    """The header's stamp in seconds, NaN when unset."""
    stamp = header.stamp
    return stamp.sec + 1e-9 * stamp.nanosec if stamp.sec or stamp.nanosec else math.nan


def name_problem(text: str, what: str) -> Optional[str]:
    """Why ``text`` cannot be a name (too long), quoting only a prefix; None when fine."""
    if len(text) > MAX_NAME_CHARS:
        return f'{what} {quote(text)} is longer than {MAX_NAME_CHARS} characters'
    return None


def yaw_of(q) -> float:
    """Rotation about z of a quaternion: atan2(2(wz + xy), 1 − 2(y² + z²))."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def quaternion_from_yaw(yaw: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def poses_of(path) -> list[tuple[float, float, float]]:
    """A nav_msgs/Path's poses as (x, y, yaw)."""
    return [(p.pose.position.x, p.pose.position.y, yaw_of(p.pose.orientation))
            for p in path.poses]


def pose_stamped(x: float, y: float, yaw: float, header: Header) -> PoseStamped:
    msg = PoseStamped(header=header)
    msg.pose.position.x, msg.pose.position.y = float(x), float(y)
    msg.pose.orientation = quaternion_from_yaw(yaw)
    return msg


def header(stamp, frame_id: str = FRAME_ID) -> Header:
    return Header(stamp=stamp, frame_id=frame_id)


def joint_state(stamp, position, velocity=(), effort=()) -> JointState:
    """A JointState of [shoulder, elbow]."""
    return JointState(header=header(stamp, ''), name=list(JOINT_NAMES),
                      position=[float(p) for p in position],
                      velocity=[float(v) for v in velocity],
                      effort=[float(e) for e in effort])


def voltage_command(command) -> Float64MultiArray:
    """A voltage pair, or a Profile (``model/profile.py``: its layout and data)."""
    if not isinstance(command, Profile):
        return Float64MultiArray(data=[float(v) for v in command])
    dims, offset, data = encode(command)
    message = Float64MultiArray(data=data)
    message.layout.data_offset = offset
    message.layout.dim = [MultiArrayDimension(label=label, size=size, stride=stride)
                          for label, size, stride in dims]
    return message


def command_of(message: Float64MultiArray):
    """A voltage_command's pair or Profile; ProfileError saying what is wrong."""
    return decode_command(message.data, [(d.label, d.size, d.stride)
                                         for d in message.layout.dim],
                          message.layout.data_offset)
