"""The bridge to an FRC robot over NetworkTables 4, without ROS.

``contract`` names every NT topic (type, unit, rate, publisher); ``conversions`` and
``rules`` turn readings and commands into each other and decide what is fresh and what is
allowed; ``tables`` holds the ntcore publishers and subscribers of each side;
``mechanism`` draws the arm as a Mechanism2d; ``wpilog`` logs a run for AdvantageScope;
``robot_sim`` is the robot-side stand-in (``frc_robot_sim``). The ROS node is
``arm_control.nodes.frc_bridge``.
"""
