"""From a goal to a checked, timed trajectory: whoever needs one asks here.

``goals`` (which points are goals, their free elbow branches), ``messages`` (the typed
requests and answers), ``port`` (``Planning``: the one way the core's requests are answered,
in-process or through the node), ``timer`` (checking a path, choosing the elbow branch by
time, timing it), ``worker`` (a request in, typed answers out: the worker's logic, pure of
processes), ``cache`` (what makes repeated goals quick, and which serves when), and a ROS
client's joint trajectory checked and retimed (``joint_trajectory``, ``trajectory_goals``).
The core (``control/``), the plan worker, the planner node and the trajectory server use it;
it imports only the floors below (model, timing; a planner is taken by its calls).
"""
