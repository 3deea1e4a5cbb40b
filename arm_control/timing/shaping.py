"""Bending the planner's path where that is faster: a batched search over sine bends.

The planner's path is short, not fast: the fastest motion often folds the elbow on the way
(less inertia and gravity torque at the shoulder) or lets one joint lead. The path is bent
by Σₕ aₕ·sin(hπσ/L) on each joint, and a pattern search over the first ``_HARMONICS``
harmonics times many shapes at once (``exact.fastest_speeds`` on a coarse grid, under the
bus sag of the unbent path). A shape counts only when its samples are free and, where the
planner's path has room to spare (``_ROOM_M`` around forbidden regions, ``_ROOM_RAD`` from the
elbow's tightest fold), keep that room (for tracking errors); the one chosen is then checked
at the world's check step.
"""

import dataclasses
import functools
import itertools
import math

import numpy as np

from arm_control.config import ArmConfig
from arm_control.model.dynamics import ArmDynamics
from arm_control.model.world import ForbiddenSpace
from arm_control.timing.bus import bus_timing, exact_timing, under_the_bus
from arm_control.timing.exact import durations, fastest_speeds
from arm_control.timing.limits import TrajectoryLimits
from arm_control.timing.path import (BlendedPath, BUS_GRID, clustered, forbidden_at, grid_for,
                                     shape_terms)
from arm_control.timing.rows import PathTerms, rows, speed_caps

# Harmonics per joint, the first batch's grid (per joint, odd: it holds 0) and span (± this
# times the path length), the refinement steps (times the length) and how many of them try
# every combination (the rest one amplitude at a time), the stages the shapes are timed on,
# the room kept (around regions, and from the elbow's tightest fold), the least gain worth
# a new shape, and the shortest move worth the search (on a shorter one a few percent is
# less than the search's own time).
_HARMONICS = 2
_GRID = 5
_SPAN = 0.35
_STEPS = (0.06, 0.03, 0.015)
_FULL_STEPS = 3
SEARCH_STAGES = 20
_ROOM_M = 0.03
_ROOM_RAD = 0.035
_MIN_GAIN = 0.01
_MIN_DURATION_S = 0.25


@functools.lru_cache(maxsize=8)
def _with_room(arm: ArmConfig, margin_rad: float = 0.0) -> ForbiddenSpace:
    """Forbidden space with every region grown by ``_ROOM_M`` more, and the elbow's tightest
    fold ``_ROOM_RAD`` wider, since tracking error carries an arm bent to the limit past it.
    With the searched space's ``margin_rad``, so that room implies free there too."""
    world = dataclasses.replace(arm.world, clearance_m=arm.world.clearance_m + _ROOM_M,
                                min_elbow_fold_rad=arm.world.min_elbow_fold_rad + _ROOM_RAD)
    return ForbiddenSpace(dataclasses.replace(arm, world=world), margin_rad)


def prove_room_cells(arm: ArmConfig, tiles: int | None = None) -> bool:
    """``ForbiddenSpace.prove_cells`` for the room the search keeps (``_with_room``), in free
    space and in the clearance."""
    return all(_with_room(arm, margin).prove_cells(tiles)
               for margin in sorted({0.0, arm.world.clearance_rad}))


def best_shape(base: BlendedPath, dynamics: ArmDynamics, forbidden, limits: TrajectoryLimits,
               start_speed: float = 0.0, steps=_STEPS):
    """(amplitudes (H, 2) of the bend Σₕ aₕ·bₕ(σ/L) that make ``base`` fastest from
    ``start_speed`` (a moving start's path is ``flat_start``), or zeros; the (σ, sag) of the
    unbent path's bus, or None; the duration the search found, inf when it found none).

    A grid of the first harmonic's amplitudes, then ``steps`` refinements over every
    combination of ±step; each batch timed at once.
    """
    zeros = np.zeros((_HARMONICS, 2))
    length = base.length
    grid = clustered(length, SEARCH_STAGES)
    fraction = grid / length
    q0, dq0, ddq0 = base(grid), base(grid, 1), base(grid, 2)
    stages = np.diff(grid)

    def timed(terms, sag_v):
        A, B, C, D, W = rows(terms, limits, sag_v)
        return fastest_speeds(A, B, C, D, W, speed_caps(limits, terms.dq), stages, start_speed)

    terms = PathTerms(dynamics, q0, dq0, ddq0)
    x, sag = under_the_bus(exact_timing(terms, grid, limits, 0.0, start_speed), terms, limits,
                           grid)
    if x is None:
        return zeros, None, math.inf
    bus = None if limits.supply is None else (grid, sag)
    unshaped_s = float(durations(stages, np.sqrt(x)[None])[0])
    if not unshaped_s >= _MIN_DURATION_S:
        return zeros, bus, unshaped_s              # a hop: the search would cost more
    roomy = _with_room(forbidden.arm, forbidden.margin_rad)
    base_roomy = np.asarray(roomy.is_free(q0), dtype=bool)
    flat = base.flat_start

    def search(shapes):
        q = q0 + shape_terms(fraction, shapes, 0, flat)
        dq = dq0 + shape_terms(fraction, shapes, 1, flat) / length
        ddq = ddq0 + shape_terms(fraction, shapes, 2, flat) / length ** 2
        # Free with room where the planner's path has room, free elsewhere (room ⇒ free).
        ok = np.asarray(roomy.is_free(q.reshape(-1, 2)), dtype=bool).reshape(q.shape[:2])
        tight = ~ok & ~base_roomy
        if np.any(tight):
            ok[tight] = np.asarray(forbidden.is_free(q[tight]), dtype=bool)
        ok = np.all(ok, axis=1)
        out = np.full(len(shapes), np.inf)
        if np.any(ok):
            speeds = timed(PathTerms(dynamics, q[ok], dq[ok], ddq[ok]), sag)
            out[ok] = durations(stages, speeds)
        return out

    levels = np.linspace(-_SPAN, _SPAN, _GRID) * length
    batch = np.zeros((_GRID ** 2, _HARMONICS, 2))
    batch[:, 0, 0], batch[:, 0, 1] = (axis.ravel() for axis in np.meshgrid(levels, levels))
    times = search(batch)
    best, best_s = zeros, unshaped_s
    if np.min(times) < best_s:
        best, best_s = batch[int(np.argmin(times))], float(np.min(times))
    every = np.array(list(itertools.product((-1.0, 0.0, 1.0), repeat=2 * _HARMONICS)))
    every = every.reshape(-1, _HARMONICS, 2)
    axes = every[np.sum(np.abs(every), axis=(1, 2)) <= 1.0]
    for index, step in enumerate(steps):
        offsets = every if index < _FULL_STEPS else axes
        batch = best + offsets * step * length
        times = search(batch)
        if np.min(times) < best_s:
            best, best_s = batch[int(np.argmin(times))], float(np.min(times))
    if not math.isfinite(best_s) or best_s >= unshaped_s * (1.0 - _MIN_GAIN):
        return zeros, bus, unshaped_s
    return best, bus, best_s


def free_shape(base: BlendedPath, shape, forbidden, step_rad):
    """``shape``, or the largest of its halves, quarters, ... whose path is free at
    ``step_rad`` (the search saw only coarse samples); None when none is."""
    for scale in (1.0, 0.5, 0.25):
        if not np.any(shape):
            break
        if len(forbidden_at(base.with_shape(scale * shape), forbidden, step_rad)) == 0:
            return scale * shape
    return None


def faster_shape(base: BlendedPath, shape, dynamics: ArmDynamics, limits: TrajectoryLimits,
                 start_speed: float = 0.0):
    """(``shape``, or None when ``base`` unbent is as fast; the (σ, sag) of the bus the one
    kept leaves, or None), both timed exactly on the bus's grid (``BUS_GRID``, the blends cut
    finely) under their own bus: on a path of many corners the search's few stages can
    misjudge, rating faster a bend that is slower than the path itself."""
    if shape is None or not np.any(shape):
        return None, None
    timed = []
    for candidate in (base, base.with_shape(shape)):
        sigma, sag, x = grid_for(candidate, BUS_GRID), None, None
        if limits.supply is not None:
            sigma, sag, x = bus_timing(candidate, dynamics, limits, 0.0, start_speed)
        if x is None:                   # no supply, or no bus found: at the nominal bus
            x = exact_timing(PathTerms.along(dynamics, candidate, sigma), sigma, limits, 0.0,
                             start_speed)(np.zeros(len(sigma)))
            sag = np.zeros(len(sigma))
        if x is None:                   # out of the exact timing's reach: no verdict
            return shape, None
        timed.append((float(durations(np.diff(sigma), np.sqrt(x)[None])[0]), (sigma, sag)))
    (unbent_s, unbent_bus), (bent_s, bent_bus) = timed
    return (shape, bent_bus) if bent_s < unbent_s else (None, unbent_bus)
