"""The arm's physics: motors, coupled two-link dynamics, kinematics, sensors. No ROS here."""
