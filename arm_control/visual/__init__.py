"""What people see: the arm's scene, run plots, the URDF and RViz markers. No rclpy here."""
