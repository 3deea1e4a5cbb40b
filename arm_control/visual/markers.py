"""The viewer's scene as a ``visualization_msgs/MarkerArray`` for RViz (messages only, no rclpy).

All in frame ``arm_base`` (x forward, y up: in RViz look along −z, e.g. the TopDownOrtho
view), namespaced so each part can be switched off in RViz: ``arm`` (the links, in the
state's colour), ``joints``, ``setpoint``, ``path`` (the tool's trace), ``goals``,
``forbidden`` (regions grown by their clearance, cut to the view), ``reach`` (the annulus).
"""

import math

from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from arm_control.config import ArmConfig, FRAME_ID
from arm_control.model.kinematics import TwoLinkKinematics
from arm_control.visual.scene import (densify, FORBIDDEN_COLOUR, GOAL_COLOUR, PATH_COLOUR,
                                      REACH_COLOUR, Scene, SETPOINT_COLOUR, state_colour,
                                      workspace_extent)

LINK_WIDTH_M = 0.06
REGION_THICKNESS_M = 0.02
CIRCLE_SEGMENTS = 120


def colour(hex_colour: str, alpha: float = 1.0) -> ColorRGBA:
    r, g, b = (int(hex_colour[i:i + 2], 16) / 255.0 for i in (1, 3, 5))
    return ColorRGBA(r=r, g=g, b=b, a=alpha)


def point(x: float, y: float) -> Point:
    return Point(x=float(x), y=float(y), z=0.0)


class MarkerBuilder:
    """Builds the MarkerArray of one arm; ``build(scene, stamp)`` for each frame."""

    def __init__(self, arm: ArmConfig, frame_id: str = FRAME_ID):
        self.arm = arm
        self.frame_id = frame_id
        self.kinematics = TwoLinkKinematics(arm.shoulder.length_m, arm.elbow.length_m)
        self.static = self._forbidden() + self._reach()

    def _marker(self, namespace: str, marker_id: int, marker_type: int) -> Marker:
        marker = Marker(ns=namespace, id=marker_id, type=marker_type, action=Marker.ADD)
        marker.header.frame_id = self.frame_id
        marker.pose.orientation.w = 1.0
        return marker

    def _deleted(self, namespace: str, marker_id: int = 0) -> Marker:
        marker = self._marker(namespace, marker_id, Marker.LINE_STRIP)
        marker.action = Marker.DELETE
        return marker

    def _forbidden(self) -> list[Marker]:
        x_min, x_max, y_min, y_max = workspace_extent(self.arm, margin_m=0.5)
        grow = self.arm.world.clearance_m
        markers = []
        for i, region in enumerate(self.arm.world.regions):
            left, right = max(region.x_min - grow, x_min), min(region.x_max + grow, x_max)
            bottom, top = max(region.y_min - grow, y_min), min(region.y_max + grow, y_max)
            if left >= right or bottom >= top:
                continue
            marker = self._marker('forbidden', i, Marker.CUBE)
            marker.pose.position = point((left + right) / 2, (bottom + top) / 2)
            marker.scale.x, marker.scale.y = right - left, top - bottom
            marker.scale.z = REGION_THICKNESS_M
            marker.color = colour(FORBIDDEN_COLOUR, 0.5)
            marker.text = region.name
            markers.append(marker)
        return markers

    def _reach(self) -> list[Marker]:
        markers = []
        for i, radius in enumerate(self.arm.reach_m):
            if radius <= 0.0:
                continue
            marker = self._marker('reach', i, Marker.LINE_STRIP)
            marker.points = [point(radius * math.cos(a), radius * math.sin(a))
                             for a in (2 * math.pi * k / CIRCLE_SEGMENTS
                                       for k in range(CIRCLE_SEGMENTS + 1))]
            marker.scale.x = 0.01
            marker.color = colour(REACH_COLOUR, 0.8)
            markers.append(marker)
        return markers

    def _links(self, namespace: str, q, hex_colour: str, alpha: float, width_m: float):
        marker = self._marker(namespace, 0, Marker.LINE_STRIP)
        marker.points = [point(0.0, 0.0), point(*self.kinematics.elbow_point(q)),
                         point(*self.kinematics.forward(q))]
        marker.scale.x = width_m
        marker.color = colour(hex_colour, alpha)
        return marker

    def build(self, scene: Scene, stamp=None) -> MarkerArray:
        markers = list(self.static)
        if scene.joint_rad is not None:
            markers.append(self._links('arm', scene.joint_rad, state_colour(scene.state), 1.0,
                                       LINK_WIDTH_M))
            joints = self._marker('joints', 0, Marker.SPHERE_LIST)
            joints.points = markers[-1].points[:2]
            joints.scale.x = joints.scale.y = joints.scale.z = 1.6 * LINK_WIDTH_M
            joints.color = colour('#212529')
            markers.append(joints)
        if scene.setpoint_rad is not None:
            markers.append(self._links('setpoint', scene.setpoint_rad, SETPOINT_COLOUR, 0.5,
                                       LINK_WIDTH_M / 3))
        else:
            markers.append(self._deleted('setpoint'))
        if len(scene.path_rad) > 0:
            path = self._marker('path', 0, Marker.LINE_STRIP)
            path.points = [point(*self.kinematics.forward(q)) for q in densify(scene.path_rad)]
            path.scale.x = 0.015
            path.color = colour(PATH_COLOUR)
            markers.append(path)
        else:
            markers.append(self._deleted('path'))
        if scene.goals_xy:
            goals = self._marker('goals', 0, Marker.SPHERE_LIST)
            goals.points = [point(x, y) for x, y in scene.goals_xy]
            goals.scale.x = goals.scale.y = goals.scale.z = 0.06
            goals.color = colour(GOAL_COLOUR)
            markers.append(goals)
        else:
            markers.append(self._deleted('goals'))
        if stamp is not None:
            for marker in markers:
                marker.header.stamp = stamp
        return MarkerArray(markers=markers)
