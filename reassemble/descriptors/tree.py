"""Closest triangles within a bound, by a bounding-box hierarchy compiled with numba.

The hierarchy is implicit: triangles sorted along a Morton curve of their box centres,
cut into leaves of ``LEAF`` consecutive triangles, and a complete binary tree over the
leaves in heap order (node i has children 2i + 1 and 2i + 2), each node the box of its
leaves. Building it is one sort and a few vectorized reductions.

A query carries its bound: a box farther than the best squared distance so far is not
opened. Started from a known upper bound (a distance the propagation of
:mod:`.closest` found, or the reach of the occupancy's ramp) it opens only the boxes
that meet that ball, so it costs about a microsecond near the surface, where Open3D's
float32 query (``RaycastingScene.compute_closest_points``) costs 4-9 us and is not exact
in float64.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from .triangle import tri_dist2

# TBB, numba's first choice, warns when the system's is too old; OpenMP ships with numba
numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

LEAF = 4  # triangles per leaf


def _morton(q: np.ndarray) -> np.ndarray:
    """(n,) uint64 Morton codes of (n, 3) integer coordinates below 2**21."""
    out = np.zeros(len(q), np.uint64)
    for a in range(3):
        x = q[:, a].astype(np.uint64)
        x = (x | (x << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
        x = (x | (x << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
        x = (x | (x << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
        x = (x | (x << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
        x = (x | (x << np.uint64(2))) & np.uint64(0x1249249249249249)
        out |= x << np.uint64(2 - a)
    return out


class TriangleTree:
    """Bounding-box hierarchy of triangles for bounded closest-triangle queries.

    Parameters
    ----------
    T : (f, 9) float64, per triangle its rows (a, b - a, c - a), as :class:`.closest.MeshDistance.T`
    """

    def __init__(self, T: np.ndarray):
        self.T = np.ascontiguousarray(T, np.float64)
        a = self.T[:, 0:3]
        b, c = a + self.T[:, 3:6], a + self.T[:, 6:9]
        lo = np.minimum(np.minimum(a, b), c)
        hi = np.maximum(np.maximum(a, b), c)
        centre = 0.5 * (lo + hi)
        q = np.zeros((len(centre), 3), np.int64)
        if len(centre):
            span = np.maximum(np.ptp(centre, axis=0), 1e-300)
            q = ((centre - centre.min(axis=0)) / span * (2**21 - 1)).astype(np.int64)
        self.order = np.argsort(_morton(q), kind="stable").astype(np.int64)
        n = len(self.order)
        leaves = max(1, -(-n // LEAF))
        depth = int(np.ceil(np.log2(leaves))) if leaves > 1 else 0
        width = 2**depth
        node_lo = np.full((2 * width - 1, 3), np.inf)
        node_hi = np.full((2 * width - 1, 3), -np.inf)
        if n:
            starts = np.arange(0, n, LEAF)
            node_lo[width - 1:width - 1 + len(starts)] = np.minimum.reduceat(lo[self.order], starts, axis=0)
            node_hi[width - 1:width - 1 + len(starts)] = np.maximum.reduceat(hi[self.order], starts, axis=0)
        for level in range(depth - 1, -1, -1):  # each level's boxes from its children's
            first, count = 2**level - 1, 2**level
            kids = 2 * np.arange(first, first + count) + 1
            node_lo[first:first + count] = np.minimum(node_lo[kids], node_lo[kids + 1])
            node_hi[first:first + count] = np.maximum(node_hi[kids], node_hi[kids + 1])
        self.node_lo, self.node_hi = node_lo, node_hi
        self.inner = width - 1  # nodes below this index are inner, the rest leaves

    def closest(self, points: np.ndarray, bound2: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """The closest triangle to each point, among those strictly nearer than its bound.

        Parameters
        ----------
        points : (n, 3) float
        bound2 : (n,) or scalar squared distance; ``inf`` for an unbounded query

        Returns
        -------
        tri : (n,) int64, the closest triangle, -1 where none is nearer than the bound
        dist2 : (n,) float64, its squared distance (the bound where there is none)
        """
        points = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
        bound2 = np.broadcast_to(np.asarray(bound2, np.float64), (len(points),)).copy()
        tri = np.full(len(points), -1, np.int64)
        _closest(points, self.T, self.order, self.node_lo, self.node_hi, self.inner, bound2, tri)
        return tri, bound2


@njit(cache=True, inline="always")
def _box_dist2(px, py, pz, lo, hi, node):
    """Squared distance from p to the box of ``node`` (0 inside; inf for an empty box)."""
    dx = max(lo[node, 0] - px, 0.0, px - hi[node, 0])
    dy = max(lo[node, 1] - py, 0.0, py - hi[node, 1])
    dz = max(lo[node, 2] - pz, 0.0, pz - hi[node, 2])
    return dx * dx + dy * dy + dz * dz


@njit(cache=True, parallel=True)
def _closest(points, T, order, lo, hi, inner, best2, tri):
    """Depth-first, nearer child first; ``best2`` and ``tri`` updated in place."""
    n = len(order)
    for s in prange(len(points)):
        px, py, pz = points[s, 0], points[s, 1], points[s, 2]
        best, bt = best2[s], tri[s]
        stack = np.empty(64, np.int64)
        stack[0] = 0
        top = 1
        while top > 0:
            top -= 1
            node = stack[top]
            if _box_dist2(px, py, pz, lo, hi, node) >= best:
                continue
            if node >= inner:
                first = (node - inner) * LEAF
                for u in range(first, min(first + LEAF, n)):
                    t = order[u]
                    d = tri_dist2(px, py, pz, T, t)
                    if d < best:
                        best, bt = d, t
            else:
                left, right = 2 * node + 1, 2 * node + 2
                dl = _box_dist2(px, py, pz, lo, hi, left)
                dr = _box_dist2(px, py, pz, lo, hi, right)
                if dl <= dr:  # the nearer child on top of the stack
                    if dr < best:
                        stack[top] = right
                        top += 1
                    if dl < best:
                        stack[top] = left
                        top += 1
                else:
                    if dl < best:
                        stack[top] = left
                        top += 1
                    if dr < best:
                        stack[top] = right
                        top += 1
        best2[s], tri[s] = best, bt
