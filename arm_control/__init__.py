"""Simulation, planning and control of a two-joint FRC-style arm."""
