"""Shortest-path trees toward the goals a robot keeps going to (its presets), built while the
planner is idle, so that a plan to one of them from anywhere needs no search: 6328's cache of
preset-to-preset paths, for any start.

The grid's graph is symmetric (an edge is cut both ways when its check fails), so Dijkstra
from a goal's grid links gives every node's distance *to* the goal, and its predecessors lead
toward it. A path read off a tree has its edges checked like any other: a blocked one is cut
and the tree built again. The tree's distances can only be optimistic, so a path whose edges
are all free is a shortest one, as with the lazy edge checks of a search. Read backwards, a
tree also gives the shortest paths *from* its goal: a robot resting on a preset needs no
search to go anywhere.
"""

import numpy as np

from arm_control.planning.graph import ConfigurationGrid, path_to

# A tree whose path keeps meeting newly blocked edges is built again at most this often.
MAX_REBUILDS = 3


def goal_key(goal) -> tuple:
    """The key of a goal configuration (rad): to the nanoradian, as IK gives it each time."""
    return tuple(np.round(np.asarray(goal, float), 9))


class GoalTrees:
    """Trees toward goal configurations on one grid."""

    def __init__(self, grid: ConfigurationGrid):
        self.grid = grid
        self._trees = {}                # goal key -> (distance, predecessor, links)

    def __contains__(self, goal) -> bool:
        return goal_key(goal) in self._trees

    def build(self, goal, links) -> None:
        """The tree toward ``goal``, joined to the grid at ``links`` (nodes, costs), as a
        search's target (``ConfigurationGrid.connections(goal, toward=True)``)."""
        nodes, costs = links
        if len(nodes) == 0:
            return
        distance, predecessor = self.grid.shortest_paths(nodes, costs)
        self._trees[goal_key(goal)] = (distance, predecessor.astype(np.int32), links)

    def rooted_at(self, q, tolerance_rad: float):
        """The goal of a tree within ``tolerance_rad`` of q on both joints, or None."""
        q = np.asarray(q, float)
        for key in self._trees:
            if np.max(np.abs(np.array(key) - q)) <= tolerance_rad:
                return np.array(key)
        return None

    def path_from(self, root, target_nodes, target_costs):
        """(nodes from the tree's goal ``root`` to the cheapest of ``target_nodes`` (joined
        at ``target_costs``), cost): the tree's path from there, reversed -- the graph is
        symmetric -- or None without a way."""
        found = self.path(root, target_nodes, target_costs)
        return None if found is None else (found[0][::-1], found[1])

    def path(self, goal, source_nodes, source_costs):
        """(nodes from a source node to one of the goal's links, cost) read off the goal's
        tree, or None without a tree or a way there."""
        for _ in range(MAX_REBUILDS + 1):
            tree = self._trees.get(goal_key(goal))
            if tree is None or len(source_nodes) == 0:
                return None
            distance, predecessor, links = tree
            totals = np.asarray(source_costs, float) + distance[source_nodes]
            best = int(np.argmin(totals))
            if not np.isfinite(totals[best]):
                return None
            nodes = path_to(int(source_nodes[best]), predecessor, self.grid.node_count)[::-1]
            if self.grid.check_path_edges(nodes):
                return nodes, float(totals[best])
            self.build(goal, links)            # an edge on it was blocked: cut, build again
        return None
