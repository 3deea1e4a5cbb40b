"""The configuration space and planning in it. No ROS here."""
