"""The arm as a WPILib Mechanism2d on NT, where Glass, Shuffleboard and AdvantageScope look.

The layout is what ``SmartDashboard.putData('Arm', mechanism)`` publishes (allwpilib's
Mechanism2d, MechanismRoot2d, MechanismLigament2d)::

    <table>/.type            'Mechanism2d'   (string, property {"SmartDashboard": ...})
    <table>/dims             [width, height] (double[]; metres here)
    <table>/backgroundColor  '#RRGGBB'
    <table>/<root>/x, y      the root's place on the canvas (double)
    <table>/<root>/<ligament>/.type   'line'
    <table>/<root>/<ligament>/angle   degrees from its parent's direction (double)
    <table>/<root>/<ligament>/length, color, weight
    a ligament hung on another is a subtable of it

Mechanism2d measures each angle from its parent, counter-clockwise, the first from +x:
exactly the shoulder and elbow angles. Two roots share the shoulder pivot: ``arm`` (the arm
as the robot reads it) and ``setpoint``, a thinner ghost of where the controller wants it.
"""

import math

from arm_control.config import ArmConfig
from arm_control.frc.contract import MECHANISM_TABLE
from arm_control.frc.tables import DRAW

BACKGROUND = '#000020'             # Mechanism2d's own default, dark blue
CANVAS_MARGIN_M = 0.2
ROOTS = {'arm': ('#EB8934', 10.0),          # Mechanism2d's default ligament orange, weight
         'setpoint': ('#5AC8FA', 4.0)}      # the ghost: light blue, thin
LINKS = ('upper_arm', 'forearm')


def ligament_paths(root: str, table: str = MECHANISM_TABLE) -> tuple[str, str]:
    """The upper arm's and the forearm's subtables (the forearm hangs on the upper arm)."""
    upper = f'{table}/{root}/{LINKS[0]}'
    return upper, f'{upper}/{LINKS[1]}'


def layout(arm: ArmConfig, table: str = MECHANISM_TABLE) -> dict:
    """Every value that does not change, by topic name: the canvas, the roots, the links."""
    half_m = arm.reach_m[1] + CANVAS_MARGIN_M
    values = {f'{table}/dims': [2.0 * half_m, 2.0 * half_m],
              f'{table}/backgroundColor': BACKGROUND}
    for root, (color, weight) in ROOTS.items():
        values[f'{table}/{root}/x'] = half_m
        values[f'{table}/{root}/y'] = half_m
        for path, joint in zip(ligament_paths(root, table), arm.joints):
            values.update({f'{path}/.type': 'line', f'{path}/length': joint.length_m,
                           f'{path}/color': color, f'{path}/weight': weight})
    return values


def angles(root: str, position, table: str = MECHANISM_TABLE) -> dict:
    """The two ligaments' angles (degrees) for joint angles ``position`` (rad)."""
    return {f'{path}/angle': math.degrees(q)
            for path, q in zip(ligament_paths(root, table), position)}


class Mechanism2dPublisher:
    """Publishes the layout once, then the arm's and the setpoint's angles as they change."""

    def __init__(self, instance, arm: ArmConfig, table: str = MECHANISM_TABLE):
        self.instance = instance
        self.table = table
        self._publishers = {}
        type_topic = instance.getStringTopic(f'{table}/.type')
        self._type = type_topic.publishEx('string', {'SmartDashboard': 'Mechanism2d'}, DRAW)
        self._type.set('Mechanism2d')
        for name, value in layout(arm, table).items():
            self._set(name, value)

    def _set(self, name: str, value) -> None:
        publisher = self._publishers.get(name)
        if publisher is None:
            topic = (self.instance.getStringTopic if isinstance(value, str) else
                     self.instance.getDoubleArrayTopic if isinstance(value, list) else
                     self.instance.getDoubleTopic)(name)
            publisher = self._publishers[name] = topic.publish(DRAW)
        publisher.set(value)

    def show(self, root: str, position) -> None:
        """Draw ``root`` ('arm' or 'setpoint') at joint angles ``position`` (rad)."""
        for name, degrees in angles(root, position, self.table).items():
            self._set(name, degrees)
