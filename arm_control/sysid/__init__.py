"""System identification of the two-joint arm: regressor, excitation, fit, log and report.

No rclpy here; ``arm_control.nodes.sysid`` is the thin shell that drives the arm with it.
"""
