"""Control: trajectories, feedback, estimation, the state machine. No ROS here."""
