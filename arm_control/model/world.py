"""The world the arm lives in: the configurations it may never take (forbidden space).

A configuration q = (shoulder, elbow) is forbidden when a joint is past its limit, the elbow
is folded tighter than ``min_elbow_fold_rad``, or any point of either link -- checked along
the whole segment, not only at its ends -- lies inside a forbidden rectangle grown by
``clearance_m``. With a ``margin_rad``, so is every configuration within that of one on
both joints: a joint-space margin, since a Cartesian one cannot hold for a shoulder pivot on
the floor's edge. Everything works on arrays of configurations at once.

Checks along paths ask about many configurations near each other, again and again, and most
are far from any forbidden region: ``FreeCells`` remembers the joint-space cells proved free
as a whole, so that only the configurations in the others get the exact check.
"""

import functools
import math

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from arm_control.config import ArmConfig


def segments_hit_rectangle(x0, y0, x1, y1, rect) -> np.ndarray:
    """Whether each segment (x0, y0)–(x1, y1) meets the closed rectangle (Liang–Barsky)."""
    x_min, y_min, x_max, y_max = rect
    dx, dy = x1 - x0, y1 - y0
    t_enter = np.zeros(np.shape(x0))
    t_leave = np.ones(np.shape(x0))
    with np.errstate(divide='ignore', invalid='ignore'):
        for p, q in ((-dx, x0 - x_min), (dx, x_max - x0), (-dy, y0 - y_min), (dy, y_max - y0)):
            parallel = p == 0.0
            t = q / np.where(parallel, 1.0, p)
            t_enter = np.where(~parallel & (p < 0), np.maximum(t_enter, t), t_enter)
            t_leave = np.where(~parallel & (p > 0), np.minimum(t_leave, t), t_leave)
            outside_parallel = parallel & (q < 0)
            t_leave = np.where(outside_parallel, -1.0, t_leave)
    return t_enter <= t_leave


class FreeCells:
    """Cells of joint space in which every configuration is free, or every one forbidden,
    found tile by tile as checks reach them.

    A cell of half-width h around c is free as a whole when the joints stay inside their
    limits (and the fold) across it, the upper arm's sweep misses every forbidden rectangle
    -- its segments for shoulder angles in [c − h, c + h] lie in the triangle of the pivot
    and the two ends pushed out by 1/cos h (the chord between them touches the arc) -- and
    the forearm at c misses every rectangle grown by δ = (L_upper + 2·L_fore)·h: across the
    cell no point of it moves more than L_upper·h + L_fore·2h. It is forbidden as a whole
    when it lies past a limit (or the fold), or a link at c meets a rectangle shrunk by δ:
    the point inside stays in the rectangle across the cell. Most configurations a path
    check rejects are deep in forbidden space, and were left to the exact test.

    With ``pad_rad``, a cell is proved clear when the free cells cover the box of half-width
    h + pad around it (an erosion of free space's cells by ⌈pad / 2h⌉ cells): every
    configuration of the cell is then free by that margin on both joints. (Proving that box
    at once, with δ grown for h + pad, proves far fewer cells: the grown δ is coarse.) A cell
    forbidden as a whole is not clear either.
    """

    HALF_WIDTH_RAD = math.radians(0.25)
    TILE = 16                          # cells a side, proved together

    def __init__(self, arm: ArmConfig, pad_rad: float = 0.0):
        h = self.HALF_WIDTH_RAD
        self.space = ForbiddenSpace(arm)
        if pad_rad <= 0.0:                 # free space's own cells, proved from the world
            motion_m = (arm.shoulder.length_m + 2.0 * arm.elbow.length_m) * h
            self.grown = ForbiddenSpace(arm, grow_m=motion_m)
            self.shrunk = ForbiddenSpace(arm, grow_m=-motion_m)
        self.cell_rad = 2.0 * h
        self.low = self.space.limits[:, 0]
        self.counts = np.ceil((self.space.limits[:, 1] - self.low) / self.cell_rad).astype(int)
        self.free = np.zeros(self.counts, dtype=bool)
        self.forbidden = np.zeros(self.counts, dtype=bool)
        self.tiles_done = np.zeros(-(-self.counts // self.TILE), dtype=bool)
        # Clear cells: free space's cells this many a side of each must all be free.
        self.base = free_cells(arm) if pad_rad > 0.0 else None
        self.pad_cells = math.ceil(pad_rad / self.cell_rad) if pad_rad > 0.0 else 0

    def lookup(self, q) -> tuple[np.ndarray, np.ndarray]:
        """Whether each configuration of q (N, 2) lies in a cell proved free, and in one
        proved forbidden (neither: the exact test decides)."""
        index = np.floor((q - self.low) / self.cell_rad).astype(np.int64)
        inside = np.all((index >= 0) & (index < self.counts), axis=-1)
        index = np.where(inside[:, None], index, 0)
        tiles = index // self.TILE
        new = inside & ~self.tiles_done[tiles[:, 0], tiles[:, 1]]
        if np.any(new):
            self._prove(np.unique(tiles[new], axis=0))
        return (inside & self.free[index[:, 0], index[:, 1]],
                inside & self.forbidden[index[:, 0], index[:, 1]])

    def prove_some(self, tiles: int | None = None) -> bool:
        """Prove ``tiles`` more tiles (None: all) ahead of the checks; True once all are."""
        left = np.argwhere(~self.tiles_done)
        if len(left):
            self._prove(left[:tiles])
        return tiles is None or len(left) <= tiles

    def block(self, low, high) -> np.ndarray:
        """The cells [low, high) on each axis, proved where not yet; outside the joints'
        travel none is free."""
        low, high = np.asarray(low), np.asarray(high)
        inner_low, inner_high = np.maximum(low, 0), np.minimum(high, self.counts)
        out = np.zeros(high - low, dtype=bool)
        if np.any(inner_high <= inner_low):
            return out
        first, last = inner_low // self.TILE, (inner_high - 1) // self.TILE + 1
        done = self.tiles_done[first[0]:last[0], first[1]:last[1]]
        if not done.all():
            self._prove(np.argwhere(~done) + first)
        inside = tuple(slice(a, b) for a, b in zip(inner_low - low, inner_high - low))
        out[inside] = self.free[inner_low[0]:inner_high[0], inner_low[1]:inner_high[1]]
        return out

    def _prove(self, tiles) -> None:
        """Prove every cell of the tiles (k, 2) at once."""
        if self.base is not None:
            self._prove_clear(tiles)
            return
        offsets = np.stack(np.meshgrid(np.arange(self.TILE), np.arange(self.TILE),
                                       indexing='ij'), axis=-1).reshape(-1, 2)
        cells = (tiles[:, None, :] * self.TILE + offsets).reshape(-1, 2)
        cells = cells[np.all(cells < self.counts, axis=-1)]
        centres = self.low + (cells + 0.5) * self.cell_rad
        h = self.HALF_WIDTH_RAD * (1.0 + 1e-6)
        space = self.space
        within = (np.all((centres - h >= space.limits[:, 0])
                         & (centres + h <= space.limits[:, 1]), axis=-1)
                  & (np.abs(centres[:, 1]) + h <= space.max_elbow_fold_rad))
        # The upper arm's sweep depends on the shoulder alone: once per shoulder cell.
        rows, row_of = np.unique(cells[:, 0], return_inverse=True)
        shoulder = (self.low[0] + (rows + 0.5) * self.cell_rad)[:, None]
        reach = space.upper_m / math.cos(h)
        ends = [(reach * np.cos(shoulder + side), reach * np.sin(shoulder + side))
                for side in (-h, h)]
        zero = np.zeros_like(shoulder)
        sweep_hits = np.zeros(len(rows), dtype=bool)
        if space.rectangles:
            bounds = space._bounds
            for x0, y0, x1, y1 in ((zero, zero, *ends[0]), (zero, zero, *ends[1]),
                                   (*ends[0], *ends[1])):
                sweep_hits |= np.any(segments_hit_rectangle(x0, y0, x1, y1, bounds), axis=-1)
            sweep_hits |= np.any(_in_triangle(bounds[0], bounds[1], (zero, zero), *ends),
                                 axis=-1)
        self.free[cells[:, 0], cells[:, 1]] = (within & ~sweep_hits[row_of]
                                               & ~self.grown.forearm_collides(centres))
        beyond = (np.any((centres + h < space.limits[:, 0]) | (centres - h > space.limits[:, 1]),
                         axis=-1)
                  | (np.abs(centres[:, 1]) - h > space.max_elbow_fold_rad))
        self.forbidden[cells[:, 0], cells[:, 1]] = beyond | self.shrunk.collides(centres)
        self.tiles_done[tiles[:, 0], tiles[:, 1]] = True

    def _prove_clear(self, tiles) -> None:
        """Each cell of the tiles clear when every base cell within ``pad_cells`` is free."""
        pad, window = self.pad_cells, 2 * self.pad_cells + 1
        for tile in tiles:
            low = tile * self.TILE
            high = np.minimum(low + self.TILE, self.counts)
            around = self.base.block(low - pad, high + pad)
            cells = (slice(low[0], high[0]), slice(low[1], high[1]))
            rows = sliding_window_view(around, window, axis=0).all(axis=-1)
            self.free[cells] = sliding_window_view(rows, window, axis=1).all(axis=-1)
            self.forbidden[cells] = self.base.forbidden[cells]
        self.tiles_done[tiles[:, 0], tiles[:, 1]] = True


def _in_triangle(x, y, a, b, c) -> np.ndarray:
    """Whether the point (x, y) lies in each triangle abc (corners as (xs, ys) arrays)."""
    def side(p, q):
        return (q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0])
    d1, d2, d3 = side(a, b), side(b, c), side(c, a)
    return ~(((d1 < 0) | (d2 < 0) | (d3 < 0)) & ((d1 > 0) | (d2 > 0) | (d3 > 0)))


@functools.lru_cache(maxsize=16)
def free_cells(arm: ArmConfig, pad_rad: float = 0.0) -> FreeCells:
    """The one ``FreeCells`` of each arm (and margin), shared by every check of it."""
    return FreeCells(arm, pad_rad)


# Checks of fewer configurations than this go through ``FreeCells``; a bigger batch (a
# planner's whole grid) is checked outright, without proving every tile on the way.
_CELLS_UP_TO = 20_000

# Where ``clear_by`` looks: the corners and edge midpoints of a square of half-width 1.
_SQUARE = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0],
                    [1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0], [0.0, 0.0]])


class ForbiddenSpace:
    """The arm's forbidden configurations, from its links, limits and world."""

    def __init__(self, arm: ArmConfig, margin_rad: float = 0.0, grow_m: float = 0.0):
        self.arm = arm
        self.margin_rad = margin_rad
        self.upper_m = arm.shoulder.length_m
        self.fore_m = arm.elbow.length_m
        # Touching a region's edge is allowed (the shoulder pivot sits on the floor's):
        # only the open interior is forbidden, so test against a rectangle a hair smaller.
        # (``grow_m``: grown further, or shrunk, for ``FreeCells``' proofs.)
        grow = arm.world.clearance_m - 1e-9 + grow_m
        self._proves_cells = grow_m != 0.0
        self._cells = self._clear_cells = None
        self.rectangles = [
            (r.name, (r.x_min - grow, r.y_min - grow, r.x_max + grow, r.y_max + grow))
            for r in arm.world.regions
            if r.x_min - grow <= r.x_max + grow and r.y_min - grow <= r.y_max + grow]
        self._bounds = np.array([rect for _, rect in self.rectangles]).T    # 4 × regions
        self.limits = np.array([[j.min_angle_rad, j.max_angle_rad] for j in arm.joints])
        self.max_elbow_fold_rad = math.pi - arm.world.min_elbow_fold_rad
        self.check_step_rad = arm.world.check_step_rad

    def _links(self, q):
        shoulder, elbow = q[..., 0], q[..., 1]
        x_elbow, y_elbow = self.upper_m * np.cos(shoulder), self.upper_m * np.sin(shoulder)
        heading = shoulder + elbow
        x_tool = x_elbow + self.fore_m * np.cos(heading)
        y_tool = y_elbow + self.fore_m * np.sin(heading)
        zero = np.zeros_like(x_elbow)
        return ((zero, zero, x_elbow, y_elbow), (x_elbow, y_elbow, x_tool, y_tool))

    def within_limits(self, q) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        return (np.all((q >= self.limits[:, 0]) & (q <= self.limits[:, 1]), axis=-1)
                & (np.abs(q[..., 1]) <= self.max_elbow_fold_rad))

    def collides(self, q, links=(0, 1)) -> np.ndarray:
        """Whether a point of either link (of ``links``: 0 the upper arm, 1 the forearm) lies
        in a forbidden rectangle (limits aside): every link and rectangle whose bounding
        boxes meet (which a hit needs) tested at once."""
        q = np.asarray(q, dtype=float)
        hit = np.zeros(q.shape[:-1], dtype=bool)
        if not self.rectangles:
            return hit
        flat = hit.reshape(-1)
        x_min, y_min, x_max, y_max = self._bounds
        for link in links:
            x0, y0, x1, y1 = (end.reshape(-1, 1) for end in self._links(q)[link])
            near = ((np.minimum(x0, x1) <= x_max) & (np.maximum(x0, x1) >= x_min)
                    & (np.minimum(y0, y1) <= y_max) & (np.maximum(y0, y1) >= y_min))
            sample, region = np.nonzero(near)
            if len(sample):
                meets = segments_hit_rectangle(x0[sample, 0], y0[sample, 0], x1[sample, 0],
                                               y1[sample, 0], self._bounds[:, region])
                flat[sample[meets]] = True
        return hit

    def forearm_collides(self, q) -> np.ndarray:
        return self.collides(q, links=(1,))

    def is_free(self, q) -> np.ndarray | bool:
        """True where q (shape (..., 2)) is allowed (and clear by ``margin_rad``)."""
        return self.clear_by(q, self.margin_rad) if self.margin_rad > 0.0 else self._free(q)

    def _free(self, q) -> np.ndarray | bool:
        q = np.asarray(q, dtype=float)
        flat = q.reshape(-1, 2)
        if self._proves_cells or len(flat) > _CELLS_UP_TO:
            free = self.within_limits(flat) & ~self.collides(flat)
        else:
            if self._cells is None:
                self._cells = free_cells(self.arm)
            free, forbidden = self._cells.lookup(flat)
            rest = ~(free | forbidden)
            if np.any(rest):
                others = flat[rest]
                free[rest] = self.within_limits(others) & ~self.collides(others)
        free = free.reshape(q.shape[:-1])
        return bool(free) if free.ndim == 0 else free

    def prove_cells(self, tiles: int | None = None) -> bool:
        """Prove the cells this space's checks look up (free space's; with a margin, the
        clear ones too), ``tiles`` more at a time (None: all), ahead of the checks: each check
        proves those it meets, so a goal into joint space no check has been to would pay for
        proving its cells in the middle of its timing. True once all are."""
        levels = [free_cells(self.arm)]
        if self.margin_rad > 0.0:
            levels.append(free_cells(self.arm, self.margin_rad))
        return all(cells.prove_some(tiles) for cells in levels)

    def why_forbidden(self, q) -> str | None:
        """A sentence saying why q is forbidden, or None when it is free."""
        q = np.asarray(q, dtype=float)
        if self.is_free(q):             # the common case, at the cost of one batch check
            return None
        if self.margin_rad > 0.0 and self._free(q):
            return f'within {math.degrees(self.margin_rad):.1f} deg of forbidden space'
        for joint, angle, (low, high) in zip(self.arm.joints, q, self.limits):
            if not low <= angle <= high:
                return (f'{joint.name} at {math.degrees(angle):.1f} deg is past its limits '
                        f'[{math.degrees(low):.1f}, {math.degrees(high):.1f}] deg')
        if abs(q[1]) > self.max_elbow_fold_rad:
            return (f'elbow at {math.degrees(q[1]):.1f} deg folds tighter than the minimum '
                    f'{math.degrees(self.arm.world.min_elbow_fold_rad):.1f} deg')
        for link_name, link in zip(('upper arm', 'forearm'), self._links(q)):
            for name, rect in self.rectangles:
                if segments_hit_rectangle(*link, rect):
                    return f'the {link_name} enters the forbidden region "{name}"'
        return None

    def segment_is_free(self, q_from, q_to, step_rad: float | None = None) -> bool:
        """Whether the straight joint-space segment is free, checked every ``step_rad``
        (default: the world's ``check_step_rad``)."""
        step_rad = step_rad or self.check_step_rad
        q_from, q_to = np.asarray(q_from, float), np.asarray(q_to, float)
        count = max(2, int(math.ceil(np.max(np.abs(q_to - q_from)) / step_rad)) + 1)
        samples = q_from + np.linspace(0.0, 1.0, count)[:, None] * (q_to - q_from)
        return bool(np.all(self.is_free(samples)))

    def path_is_free(self, path, step_rad: float | None = None) -> bool:
        path = np.asarray(path, float)
        return all(self.segment_is_free(a, b, step_rad) for a, b in zip(path[:-1], path[1:]))

    def clear_by(self, q, margin_rad: float) -> np.ndarray | bool:
        """Free, and so is every configuration within ``margin_rad`` of q on both joints
        (checked at the corners and edge midpoints of that square; for this space's own
        margin, at once where q lies in a cell proved free by it as a whole)."""
        q = np.asarray(q, dtype=float)
        flat = q.reshape(-1, 2)
        if margin_rad != self.margin_rad or self._proves_cells or len(flat) > _CELLS_UP_TO:
            clear = np.all(self._free(flat[:, None, :] + margin_rad * _SQUARE), axis=-1)
        else:
            if self._clear_cells is None:
                self._clear_cells = free_cells(self.arm, margin_rad)
            clear, forbidden = self._clear_cells.lookup(flat)
            rest = ~(clear | forbidden)
            if np.any(rest):
                clear[rest] = np.all(self._free(flat[rest][:, None, :] + margin_rad * _SQUARE),
                                     axis=-1)
        clear = clear.reshape(q.shape[:-1])
        return bool(clear) if clear.ndim == 0 else clear

    def nearest_clear(self, q, margin_rad: float, reach_rad: float) -> np.ndarray | None:
        """The configuration nearest q (joint-space distance, in steps of ``margin_rad``/2
        and 5 deg of direction) that is ``clear_by`` the margin and reached by a straight
        segment that, once free, stays free; None within ``reach_rad``."""
        q = np.asarray(q, dtype=float)
        angles = np.radians(np.arange(0.0, 360.0, 5.0))
        directions = np.stack([np.cos(angles), np.sin(angles)], axis=-1)
        # Radius by radius, each ring's candidates and their segments checked at once: the
        # nearest ring with a way there ends the search (a few ms, not a scan of them all).
        for radius in np.arange(0.0, reach_rad + 1e-12, margin_rad / 2.0):
            ring = q + radius * directions[:1 if radius == 0.0 else None]
            clear = ring[np.asarray(self.clear_by(ring, margin_rad), dtype=bool).reshape(-1)]
            if len(clear) == 0:
                continue
            count = max(2, int(math.ceil(radius / self.check_step_rad)) + 1)
            steps = np.linspace(0.0, 1.0, count)[None, :, None]
            free = np.asarray(self._free(q + steps * (clear[:, None, :] - q)), dtype=bool)
            # Once free, stays free: no forbidden sample after the first free one.
            first_free = np.argmax(free, axis=1)
            after = np.arange(count)[None, :] >= first_free[:, None]
            good = np.all(free | ~after, axis=1)
            if np.any(good):
                return clear[np.argmax(good)]
        return None

    def lowest_point_m(self, q) -> np.ndarray:
        """The lowest y of either link (the shoulder pivot is at y = 0): floor clearance."""
        (_, _, _, y_elbow), (_, _, _, y_tool) = self._links(np.asarray(q, float))
        return np.minimum(np.minimum(y_elbow, y_tool), 0.0)

    def to_joint_range(self, angle: float, joint_index: int) -> float | None:
        """The representative angle + 2πk inside the joint's limits nearest ``angle``, or None."""
        low, high = self.limits[joint_index]
        turn = 2.0 * math.pi
        k_low, k_high = math.ceil((low - angle) / turn), math.floor((high - angle) / turn)
        if k_low > k_high:
            return None
        k = min(range(k_low, k_high + 1), key=abs)
        return angle + 2 * math.pi * k
