"""Runs of the arm on disk and in memory: rosbag2 MCAP bags (``bag``) and time-stamped
streams for plotting (``recording``)."""
