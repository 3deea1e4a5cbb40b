"""The configuration-space grid and Dijkstra's algorithm over it.

The grid covers each joint's travel [min_angle_rad, max_angle_rad] in continuous angle, one
node per cell centre, ``grid_resolution_rad`` apart on both axes. This is the torus of the
arm paper (§3.1) cut where the hard stops cut it: across ±180° neighbours join wherever the
joint's travel crosses it (the default shoulder, -20° to 200°, does), and never across a
hard stop, so a path can never ask a joint to wrap through its stop. Where a travel is longer
than a turn, θ and θ + 2π are different nodes: the joint is in a different place.

Neighbours are 8-connected. An edge costs the joint travel |Δθa| + |Δθb| (the paper's
cost, §3.2) plus ``TIE_BREAK`` times its length, so that among the many paths of equal
travel the straightest (diagonal-first) wins; the added cost is far below one cell.

Nodes are checked at start. Edges are checked lazily (Bohlin and Kavraki, 2000): the search
runs on the optimistic graph, the edges of the path it returns are checked at
``check_step_rad``, any that are blocked are cut and the search runs again. Dijkstra on a
graph whose unchecked edges may only be removed returns the shortest path of the true graph
once every edge on it is checked free, so this is exact, and start-up stays cheap.

Node id = i · n_elbow + j for shoulder cell i and elbow cell j. Each node has 8 slots in the
CSR arrays, slot k pointing to its neighbour in ``DIRECTIONS[k]``; a missing or blocked
edge points back at its own node (a self-loop, which no shortest path takes).
"""

from dataclasses import dataclass
import heapq
import math

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from arm_control.model.world import ForbiddenSpace

# Neighbour steps (d_shoulder, d_elbow); DIRECTIONS[7 - k] is the opposite of DIRECTIONS[k].
DIRECTIONS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
TIE_BREAK = 1e-5
# Samples per batch of collision checks: bounds the memory of one vectorised check.
CHECK_BATCH = 200_000
# Edges from the virtual source of a search: the start's connections, (2 · 4)² at most.
SOURCE_SLOTS = 64


@dataclass(frozen=True)
class Axis:
    """One joint's cells: ``count`` centres ``step_rad`` apart from ``first_rad``."""

    first_rad: float
    step_rad: float
    count: int

    @classmethod
    def for_travel(cls, low_rad: float, high_rad: float, step_rad: float) -> 'Axis':
        """Cells centred in the travel, every centre at least half a cell inside the stops."""
        count = max(1, int(math.floor((high_rad - low_rad) / step_rad + 1e-9)))
        first = low_rad + 0.5 * ((high_rad - low_rad) - (count - 1) * step_rad)
        return cls(first, step_rad, count)

    def centres(self) -> np.ndarray:
        return self.first_rad + self.step_rad * np.arange(self.count)

    def fractional_index(self, angle_rad: float) -> float:
        return (angle_rad - self.first_rad) / self.step_rad


def segment_samples(q_from, q_to, step_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """The points ``ForbiddenSpace.segment_is_free`` checks, for many segments at once.

    q_from, q_to: (E, 2). Returns (samples (S, 2), the index in them of each segment's
    first): each segment's own samples, one after another.
    """
    q_from, q_to = np.asarray(q_from, float), np.asarray(q_to, float)
    delta = q_to - q_from
    counts = np.maximum(2, np.ceil(np.max(np.abs(delta), axis=-1) / step_rad).astype(int) + 1)
    firsts = np.cumsum(counts) - counts
    segment = np.repeat(np.arange(len(counts)), counts)
    fraction = (np.arange(counts.sum()) - firsts[segment]) * (1.0 / (counts[segment] - 1))
    return q_from[segment] + fraction[:, None] * delta[segment], firsts


def segments_free(forbidden: ForbiddenSpace, q_from, q_to, step_rad: float) -> np.ndarray:
    """Whether each straight joint-space segment is free, checked every ``step_rad``."""
    q_from = np.asarray(q_from, float).reshape(-1, 2)
    q_to = np.asarray(q_to, float).reshape(-1, 2)
    free = np.ones(len(q_from), dtype=bool)
    if len(q_from) == 0:
        return free
    longest = np.max(np.abs(q_to - q_from))
    per_segment = max(2, int(math.ceil(longest / step_rad)) + 1)
    chunk = max(1, CHECK_BATCH // per_segment)
    for begin in range(0, len(q_from), chunk):
        end = begin + chunk
        samples, firsts = segment_samples(q_from[begin:end], q_to[begin:end], step_rad)
        free[begin:end] = np.logical_and.reduceat(forbidden.is_free(samples), firsts)
    return free


class ConfigurationGrid:
    """The grid of (shoulder, elbow) cells, which are free, and the graph between them."""

    def __init__(self, forbidden: ForbiddenSpace, resolution_rad: float, check_step_rad: float):
        self.forbidden = forbidden
        self.resolution_rad = resolution_rad
        self.check_step_rad = check_step_rad
        (s_low, s_high), (e_low, e_high) = forbidden.limits
        self.shoulder = Axis.for_travel(s_low, s_high, resolution_rad)
        self.elbow = Axis.for_travel(e_low, e_high, resolution_rad)
        shape = (self.shoulder.count, self.elbow.count)
        self.node_count = shape[0] * shape[1]
        grid = np.stack(np.meshgrid(self.shoulder.centres(), self.elbow.centres(),
                                    indexing='ij'), axis=-1)
        self.configurations = grid.reshape(-1, 2)          # (node_count, 2), rad
        self.free = np.asarray(forbidden.is_free(grid)).reshape(shape)   # [i, j]
        self._build_edges()

    def _build_edges(self) -> None:
        n_s, n_e = self.shoulder.count, self.elbow.count
        i, j = np.meshgrid(np.arange(n_s), np.arange(n_e), indexing='ij')
        node = (i * n_e + j).ravel()
        free = self.free.ravel()
        indices = np.empty((self.node_count, len(DIRECTIONS)), dtype=np.int32)
        weights = np.empty((self.node_count, len(DIRECTIONS)))
        for k, (d_s, d_e) in enumerate(DIRECTIONS):
            i_to, j_to = (i + d_s).ravel(), (j + d_e).ravel()
            inside = (i_to >= 0) & (i_to < n_s) & (j_to >= 0) & (j_to < n_e)
            to = np.where(inside, i_to * n_e + j_to, node)
            usable = inside & free & free[to]
            indices[:, k] = np.where(usable, to, node)
            step = self.resolution_rad * np.array([abs(d_s), abs(d_e)])
            weights[:, k] = step.sum() + TIE_BREAK * math.hypot(*step)
        # The search graph has one more row, a virtual source, whose SOURCE_SLOTS edges each
        # query rewrites in place (unused ones loop back to it); no edge leads into it.
        slots = self.node_count * len(DIRECTIONS)
        source = self.node_count
        all_indices = np.full(slots + SOURCE_SLOTS, source, dtype=np.int32)
        all_weights = np.zeros(slots + SOURCE_SLOTS)
        all_indices[:slots], all_weights[:slots] = indices.ravel(), weights.ravel()
        self.indices, self.weights = all_indices[:slots], all_weights[:slots]      # views
        self._source_indices, self._source_weights = all_indices[slots:], all_weights[slots:]
        self.indptr = np.arange(0, slots + 1, len(DIRECTIONS), dtype=np.int32)
        self._search_graph = csr_matrix(
            (all_weights, all_indices, np.append(self.indptr, slots + SOURCE_SLOTS)),
            shape=(source + 1, source + 1))
        assert np.shares_memory(self._search_graph.indices, all_indices)
        self.checked_free = np.zeros(slots, dtype=bool)
        self.blocked_edges = 0
        self._lists = None
        base = csr_matrix((self.weights, self.indices, self.indptr),
                          shape=(self.node_count, self.node_count))
        self.component_count, self.components = connected_components(
            base, directed=True, connection='weak')

    # Cells and nodes

    def node_of(self, i: int, j: int) -> int:
        return i * self.elbow.count + j

    def cell_of(self, node: int) -> tuple[int, int]:
        return divmod(int(node), self.elbow.count)

    def nodes_near(self, q, radius_cells: int) -> np.ndarray:
        """Free nodes in the (2r × 2r) block of cells around q (r cells each side)."""
        corner = [int(math.floor(axis.fractional_index(angle)))
                  for axis, angle in zip((self.shoulder, self.elbow), q)]
        spans = []
        for base, axis in zip(corner, (self.shoulder, self.elbow)):
            spans.append(np.arange(max(0, base - radius_cells + 1),
                                   min(axis.count, base + radius_cells + 1)))
        if len(spans[0]) == 0 or len(spans[1]) == 0:
            return np.zeros(0, dtype=int)
        i, j = np.meshgrid(*spans, indexing='ij')
        keep = self.free[i, j]
        return (i[keep] * self.elbow.count + j[keep]).astype(int)

    def connections(self, q, toward: bool,
                    radius_cells=(1, 2, 4)) -> tuple[np.ndarray, np.ndarray]:
        """Free nodes joined to q by a checked straight segment, and the cost of each.

        ``toward``: check the segment node → q (q is a goal) rather than q → node.
        The block around q grows until some node connects.
        """
        q = np.asarray(q, float)
        for radius in radius_cells:
            nodes = self.nodes_near(q, radius)
            if len(nodes) == 0:
                continue
            others = self.configurations[nodes]
            ends = np.broadcast_to(q, others.shape)
            free = (segments_free(self.forbidden, others, ends, self.check_step_rad) if toward
                    else segments_free(self.forbidden, ends, others, self.check_step_rad))
            if np.any(free):
                nodes, others = nodes[free], others[free]
                return nodes, np.abs(others - q).sum(axis=1)
        return np.zeros(0, dtype=int), np.zeros(0)

    # Edges, checked lazily

    def _slot(self, node_from: int, node_to: int) -> int:
        i, j = self.cell_of(node_from)
        i_to, j_to = self.cell_of(node_to)
        return node_from * len(DIRECTIONS) + DIRECTIONS.index((i_to - i, j_to - j))

    def check_path_edges(self, nodes) -> bool:
        """Check the not-yet-checked grid edges along ``nodes``; cut the blocked ones.

        Returns True when every edge on the path is free.
        """
        nodes = np.asarray(nodes, dtype=int)
        if len(nodes) < 2:
            return True
        slots = np.array([self._slot(a, b) for a, b in zip(nodes[:-1], nodes[1:])])
        unknown = ~self.checked_free[slots]
        if not np.any(unknown):
            return True
        slots = slots[unknown]
        a = nodes[:-1][unknown]
        b = nodes[1:][unknown]
        free = segments_free(self.forbidden, self.configurations[a], self.configurations[b],
                             self.check_step_rad)
        reverse = b * len(DIRECTIONS) + (len(DIRECTIONS) - 1 - slots % len(DIRECTIONS))
        self.checked_free[slots[free]] = True
        self.checked_free[reverse[free]] = True
        if np.all(free):
            return True
        self.indices[slots[~free]] = a[~free]
        self.indices[reverse[~free]] = b[~free]
        self.blocked_edges += int(np.count_nonzero(~free))
        self._lists = None
        return False

    def check_all_edges(self) -> int:
        """Check every edge between free neighbours now (eager, as a slow start-up would);
        returns how many are blocked."""
        slots = np.flatnonzero(
            self.indices != np.repeat(np.arange(self.node_count), len(DIRECTIONS)))
        slots = slots[~self.checked_free[slots]]
        a = slots // len(DIRECTIONS)
        b = self.indices[slots].astype(int)
        forward = a < b                                    # each edge once
        slots, a, b = slots[forward], a[forward], b[forward]
        free = segments_free(self.forbidden, self.configurations[a], self.configurations[b],
                             self.check_step_rad)
        reverse = b * len(DIRECTIONS) + (len(DIRECTIONS) - 1 - slots % len(DIRECTIONS))
        self.checked_free[slots[free]] = True
        self.checked_free[reverse[free]] = True
        self.indices[slots[~free]] = a[~free]
        self.indices[reverse[~free]] = b[~free]
        blocked = int(np.count_nonzero(~free))
        self.blocked_edges += blocked
        self._lists = None
        return blocked

    # Search

    def shortest_path(self, source_nodes, source_costs, target_nodes, target_costs,
                      method: str = 'scipy', max_searches: int = 50, guess: float = math.inf):
        """The cheapest checked path virtual source → grid → virtual target.

        Sources and targets are grid nodes with the cost of joining them (the exact start
        and goal configurations lie off the grid). ``guess``: a likely bound on the cost;
        the search first explores only that far (exact when it finds a target: Dijkstra
        settles nodes in order of distance), then, if it found none, everywhere.
        Returns (nodes, cost, target index) or None when no path exists; raises
        RuntimeError past ``max_searches`` re-searches.
        """
        return self.shortest_path_each(source_nodes, source_costs,
                                       [(target_nodes, target_costs)], method, max_searches,
                                       guess)[0]

    def shortest_path_each(self, source_nodes, source_costs, groups, method: str = 'scipy',
                           max_searches: int = 50, guess: float = math.inf):
        """``shortest_path`` to each group of targets ((nodes, costs) pairs, e.g. the
        goal's elbow branches), all from the same searches: a blocked edge found on one
        group's path is cut and the search runs again for the groups still open."""
        groups = [(np.asarray(nodes, dtype=int), np.asarray(costs, dtype=float))
                  for nodes, costs in groups]
        found = [None] * len(groups)
        open_groups = [g for g, (nodes, _) in enumerate(groups) if len(nodes)]
        if len(source_nodes) == 0:
            return found
        limit = guess if method == 'scipy' else math.inf   # heapq stops at the targets
        for _ in range(max_searches):
            if not open_groups:
                return found
            targets = np.concatenate([groups[g][0] for g in open_groups])
            distance, predecessor = self.shortest_paths(source_nodes, source_costs, method,
                                                        targets, limit)
            still, wider = [], False
            for g in open_groups:
                nodes, costs = groups[g]
                totals = distance[nodes] + costs
                best = int(np.argmin(totals))
                if not totals[best] <= limit:
                    if not math.isinf(limit):              # the guess was short
                        still.append(g)
                        wider = True
                    continue                               # else no path: None
                path = path_to(int(nodes[best]), predecessor, self.node_count)
                if self.check_path_edges(path):
                    found[g] = (path, float(totals[best]), best)
                else:
                    still.append(g)
            open_groups = still
            if wider:
                limit = math.inf
        if not open_groups:
            return found
        raise RuntimeError(f'{max_searches} searches in a row found a blocked grid edge')

    def shortest_paths(self, source_nodes, source_costs, method: str = 'scipy',
                       targets=None, limit: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
        """Dijkstra from a virtual source joined to ``source_nodes`` at ``source_costs``.

        Returns (distance, predecessor) over the nodes; predecessor == node_count marks a
        node reached straight from the source, -1 one never reached. ``method``: 'scipy'
        (scipy.sparse.csgraph.dijkstra, the whole graph) or 'heapq' (plain Python, stops
        once every node of ``targets`` is settled).
        """
        source_nodes = np.asarray(source_nodes, dtype=np.int32)
        source_costs = np.asarray(source_costs, dtype=float)
        if method == 'heapq':
            if self._lists is None:
                self._lists = (self.indptr.tolist(), self.indices.tolist(),
                               self.weights.tolist())
            return dijkstra_heapq(*self._lists, self.node_count, zip(source_nodes.tolist(),
                                  source_costs.tolist()), targets)
        if method != 'scipy':
            raise ValueError(f"unknown search method '{method}': expected 'scipy' or 'heapq'")
        if len(source_nodes) > SOURCE_SLOTS:
            raise ValueError(f'{len(source_nodes)} source nodes: at most {SOURCE_SLOTS}')
        source = self.node_count
        self._source_indices[:] = source
        self._source_weights[:] = 0.0
        self._source_indices[:len(source_nodes)] = source_nodes
        self._source_weights[:len(source_nodes)] = source_costs
        distance, predecessor = dijkstra(self._search_graph, directed=True, indices=source,
                                         return_predecessors=True, limit=limit)
        predecessor = predecessor[:source].astype(np.int64)
        predecessor[predecessor < 0] = -1
        return distance[:source], predecessor


def dijkstra_heapq(indptr, indices, weights, node_count: int, sources,
                   targets=None) -> tuple[np.ndarray, np.ndarray]:
    """Plain Dijkstra with a binary heap over CSR lists, from (node, cost) sources.

    Predecessor == node_count marks a node reached straight from a source. With ``targets``
    it stops once all of them are settled (the rest of ``distance`` is then an upper bound).
    """
    distance = [math.inf] * node_count
    predecessor = [-1] * node_count
    heap = []
    for node, cost in sources:
        if cost < distance[node]:
            distance[node] = cost
            predecessor[node] = node_count
            heap.append((cost, node))
    heapq.heapify(heap)
    remaining = set(int(t) for t in targets) if targets is not None else None
    settled = [False] * node_count
    while heap:
        cost, node = heapq.heappop(heap)
        if settled[node]:
            continue
        settled[node] = True
        if remaining is not None:
            remaining.discard(node)
            if not remaining:
                break
        for slot in range(indptr[node], indptr[node + 1]):
            neighbour = indices[slot]
            candidate = cost + weights[slot]
            if candidate < distance[neighbour]:
                distance[neighbour] = candidate
                predecessor[neighbour] = node
                heapq.heappush(heap, (candidate, neighbour))
    return np.array(distance), np.array(predecessor, dtype=np.int64)


def path_to(node: int, predecessor, node_count: int) -> list[int]:
    """The nodes from the source's first node to ``node``, following predecessors."""
    path = []
    while node != node_count:
        if node < 0 or len(path) > node_count:
            raise ValueError('broken predecessor chain')
        path.append(int(node))
        node = predecessor[node]
    return path[::-1]
