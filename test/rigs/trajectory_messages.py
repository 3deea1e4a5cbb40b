"""Joint trajectories as a ROS client sends them: a JointTrajectory message from rows of
(time, positions[, velocities[, accelerations]]), and a FollowJointTrajectory goal of one."""

from builtin_interfaces.msg import Duration
from control_msgs.action import FollowJointTrajectory
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint


def duration(t_s: float) -> Duration:
    return Duration(sec=int(t_s), nanosec=int(round((t_s - int(t_s)) * 1e9)))


def trajectory(names, rows) -> JointTrajectory:
    """rows: (time, positions[, velocities[, accelerations]])."""
    message = JointTrajectory(joint_names=list(names))
    for row in rows:
        point = JointTrajectoryPoint(positions=[float(v) for v in row[1]],
                                     time_from_start=duration(row[0]))
        if len(row) > 2:
            point.velocities = [float(v) for v in row[2]]
        if len(row) > 3:
            point.accelerations = [float(v) for v in row[3]]
        message.points.append(point)
    return message


def goal_of(names, rows, **fields) -> FollowJointTrajectory.Goal:
    return FollowJointTrajectory.Goal(trajectory=trajectory(names, rows), **fields)
