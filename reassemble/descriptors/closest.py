"""Distances to a triangle mesh in a band of grid voxels, by closest-triangle propagation.

Layer 0 is the voxels nearest points spread over every triangle at most a voxel apart,
each with the closest of the triangles that marked it. The band then grows outward layer
by layer (26 neighbours). A voxel starts from the closest triangles of its face neighbours
of earlier layers and descends on the mesh: it moves to any triangle sharing a vertex with
the current one that is closer, until none is. A step costs a dozen exact point-triangle
distances and the start is within about a voxel of the answer, so a voxel costs a few
dozen distances whatever the mesh's size, where an unbounded tree query (Open3D, libigl's
AABB) costs 7-19 us and slows down with the distance from the surface.

The descent finds the closest triangle wherever the distance over the mesh has one minimum
near the start. Where it has several (two fronts meeting, concave pockets),
:class:`MeshDistance` finds the voxels that may be wrong and makes them exact (its Notes).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from .tree import TriangleTree
from .triangle import tri_closest, tri_dist2

# TBB, numba's first choice, warns when the system's is too old; OpenMP ships with numba
numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]


@njit(cache=True, inline="always")
def _closer(px, py, pz, T, g, bt, best):
    """(triangle, squared distance): ``g`` where it is closer to the point than ``best``
    (that of triangle ``bt``), else ``bt``, ``best``."""
    if g != bt:
        d = tri_dist2(px, py, pz, T, g)
        if d < best:
            return g, d
    return bt, best


@njit(cache=True, inline="always")
def _around(q, nx, ny, nz, cells, offset2):
    """The voxels around voxel ``q`` (a flat index): itself and its 26 neighbours that are
    in the grid, written to ``cells`` (flat indices) and ``offset2`` (squared offsets, in
    voxels); returns how many."""
    k = q % nz
    j = (q // nz) % ny
    i = q // (ny * nz)
    n = 0
    for di in range(-1, 2):
        ii = i + di
        if ii < 0 or ii >= nx:
            continue
        for dj in range(-1, 2):
            jj = j + dj
            if jj < 0 or jj >= ny:
                continue
            for dk in range(-1, 2):
                kk = k + dk
                if kk < 0 or kk >= nz:
                    continue
                cells[n] = (ii * ny + jj) * nz + kk
                offset2[n] = di * di + dj * dj + dk * dk
                n += 1
    return n


@njit(cache=True, parallel=True)
def _feet(where, sel, T, tri, origin, h, ny, nz, foot):
    """``foot[s]``: the point of triangle ``tri[s]`` closest to voxel ``where[s]``, for s in ``sel``."""
    for u in prange(len(sel)):
        s = sel[u]
        q = where[s]
        k = q % nz
        j = (q // nz) % ny
        i = q // (ny * nz)
        foot[s, 0], foot[s, 1], foot[s, 2] = tri_closest(origin[0] + h * i, origin[1] + h * j,
                                                          origin[2] + h * k, T, tri[s])


@njit(cache=True, parallel=True)
def _jumps(where, sel, foot, dist2, h, nx, ny, nz, pos, exact2, spread):
    """Of the voxels ``sel`` (positions in ``where``): those within the exact zone whose
    closest point moves more than ``spread`` times as far as the voxel does, to some
    neighbour's: where descents may stop at a local minimum. (len(sel),) bool."""
    flag = np.zeros(len(sel), np.bool_)
    s2 = spread * spread
    for u in prange(len(sel)):
        s = sel[u]
        if dist2[s] > exact2:
            continue
        cells, offset2 = np.empty(27, np.int64), np.empty(27, np.int64)
        for t in range(_around(where[s], nx, ny, nz, cells, offset2)):
            o = pos[cells[t]]
            if o < 0:
                continue
            ex = foot[o, 0] - foot[s, 0]
            ey = foot[o, 1] - foot[s, 1]
            ez = foot[o, 2] - foot[s, 2]
            if ex * ex + ey * ey + ez * ez > s2 * h * h * offset2[t]:
                flag[u] = True
                break
    return flag


@njit(cache=True, parallel=True)
def _relax(where, sel, T, nptr, nidx, tri, dist2, origin, h, nx, ny, nz, pos, new_tri, new_dist2):
    """For the voxels ``sel`` (positions in ``where``): the best of every neighbour's closest
    triangle, then the descent; written to new_tri, new_dist2."""
    for u in prange(len(sel)):
        s = sel[u]
        q = where[s]
        k = q % nz
        j = (q // nz) % ny
        i = q // (ny * nz)
        px, py, pz = origin[0] + h * i, origin[1] + h * j, origin[2] + h * k
        bt = tri[s]
        best = dist2[s]
        cells, offset2 = np.empty(27, np.int64), np.empty(27, np.int64)
        for t in range(_around(q, nx, ny, nz, cells, offset2)):
            o = pos[cells[t]]
            if o >= 0:
                bt, best = _closer(px, py, pz, T, tri[o], bt, best)
        if bt != tri[s]:
            bt, best = _descend(px, py, pz, T, nptr, nidx, bt, best)
        new_tri[s] = bt
        new_dist2[s] = best


@njit(cache=True)
def _dilate(sel, where, nx, ny, nz, pos):
    """The positions ``sel`` and their 26 neighbours' (that are in ``where``), ascending."""
    mark = np.zeros(len(where), np.bool_)
    cells, offset2 = np.empty(27, np.int64), np.empty(27, np.int64)
    for u in range(len(sel)):
        for t in range(_around(where[sel[u]], nx, ny, nz, cells, offset2)):
            o = pos[cells[t]]
            if o >= 0:
                mark[o] = True
    return np.flatnonzero(mark)


@njit(cache=True)
def _face_neighbours(F, n_vertices):
    """CSR (ptr (f + 1,), idx) of the faces sharing a vertex with each face, itself excluded."""
    nf = F.shape[0]
    deg = np.zeros(n_vertices + 1, np.int64)
    for t in range(nf):
        for k in range(3):
            deg[F[t, k] + 1] += 1
    vptr = np.cumsum(deg)
    vidx = np.empty(vptr[-1], np.int64)
    fill = vptr[:-1].copy()
    for t in range(nf):
        for k in range(3):
            v = F[t, k]
            vidx[fill[v]] = t
            fill[v] += 1
    ptr = np.zeros(nf + 1, np.int64)
    for t in range(nf):
        ptr[t + 1] = ptr[t] + vptr[F[t, 0] + 1] - vptr[F[t, 0]] + vptr[F[t, 1] + 1] - vptr[F[t, 1]] \
            + vptr[F[t, 2] + 1] - vptr[F[t, 2]]
    idx = np.empty(ptr[-1], np.int64)
    count = np.zeros(nf, np.int64)
    for t in prange(nf):
        n = 0
        base = ptr[t]
        for k in range(3):
            v = F[t, k]
            for j in range(vptr[v], vptr[v + 1]):
                g = vidx[j]
                if g == t:
                    continue
                seen = False
                for q in range(n):
                    if idx[base + q] == g:
                        seen = True
                        break
                if not seen:
                    idx[base + n] = g
                    n += 1
        count[t] = n
    # compact
    out_ptr = np.zeros(nf + 1, np.int64)
    for t in range(nf):
        out_ptr[t + 1] = out_ptr[t] + count[t]
    out = np.empty(out_ptr[-1], np.int64)
    for t in range(nf):
        out[out_ptr[t]:out_ptr[t + 1]] = idx[ptr[t]:ptr[t] + count[t]]
    return out_ptr, out


@njit(cache=True, inline="always")
def _descend(px, py, pz, T, nptr, nidx, t, best):
    """From triangle t at squared distance best, move to closer vertex-sharing triangles."""
    while True:
        nt = t
        for k in range(nptr[t], nptr[t + 1]):
            g = nidx[k]
            d = tri_dist2(px, py, pz, T, g)
            if d < best:
                best = d
                nt = g
        if nt == t:
            return t, best
        t = nt


@njit(cache=True)
def _seeds(T, origin, h, nx, ny, nz, layer, tri, dist2):
    """Layer 0: the voxels nearest points spread over every triangle at most h apart, each
    with the closest of the triangles that marked it."""
    nf = T.shape[0]
    front = np.empty(16, np.int64)
    m = 0
    for t in range(nf):
        e1 = np.sqrt(T[t, 3] ** 2 + T[t, 4] ** 2 + T[t, 5] ** 2)
        e2 = np.sqrt(T[t, 6] ** 2 + T[t, 7] ** 2 + T[t, 8] ** 2)
        e3 = np.sqrt((T[t, 6] - T[t, 3]) ** 2 + (T[t, 7] - T[t, 4]) ** 2 + (T[t, 8] - T[t, 5]) ** 2)
        n = max(0, int(np.ceil(max(e1, e2, e3) / h)) - 1)
        for u in range(n + 1):
            for v in range(n + 1 - u):
                fu, fv = (u + 1.0 / 3.0) / (n + 1.0), (v + 1.0 / 3.0) / (n + 1.0)
                x = T[t, 0] + fu * T[t, 3] + fv * T[t, 6]
                y = T[t, 1] + fu * T[t, 4] + fv * T[t, 7]
                z = T[t, 2] + fu * T[t, 5] + fv * T[t, 8]
                i = int(np.rint((x - origin[0]) / h))
                j = int(np.rint((y - origin[1]) / h))
                k = int(np.rint((z - origin[2]) / h))
                if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz:
                    continue
                q = (i * ny + j) * nz + k
                d = tri_dist2(origin[0] + h * i, origin[1] + h * j, origin[2] + h * k, T, t)
                if layer[q] < 0:
                    layer[q] = 0
                    tri[q] = t
                    dist2[q] = d
                    if m == len(front):
                        grown = np.empty(2 * m, np.int64)
                        grown[:m] = front
                        front = grown
                    front[m] = q
                    m += 1
                elif d < dist2[q]:
                    tri[q] = t
                    dist2[q] = d
    return front[:m].copy()


@njit(cache=True, parallel=True)
def _solve_layer(front, L, T, nptr, nidx, origin, h, nx, ny, nz, layer, tri, dist2, descend2):
    """Closest triangle of every voxel of ``front`` (layer L): the best of its own start and
    the closest triangles of its face neighbours of earlier layers (of its other neighbours
    when it has none), then the descent where that is within ``sqrt(descend2)``."""
    for s in prange(len(front)):
        q = front[s]
        k = q % nz
        j = (q // nz) % ny
        i = q // (ny * nz)
        px, py, pz = origin[0] + h * i, origin[1] + h * j, origin[2] + h * k
        bt = tri[q]
        best = np.inf
        if bt >= 0:
            best = tri_dist2(px, py, pz, T, bt)
        found = False
        for a in range(6):
            ii, jj, kk = i, j, k
            if a == 0:
                ii -= 1
            elif a == 1:
                ii += 1
            elif a == 2:
                jj -= 1
            elif a == 3:
                jj += 1
            elif a == 4:
                kk -= 1
            else:
                kk += 1
            if ii < 0 or jj < 0 or kk < 0 or ii >= nx or jj >= ny or kk >= nz:
                continue
            r = (ii * ny + jj) * nz + kk
            lr = layer[r]
            if lr < 0 or lr >= L:
                continue
            found = True
            bt, best = _closer(px, py, pz, T, tri[r], bt, best)
        if not found:
            cells, offset2 = np.empty(27, np.int64), np.empty(27, np.int64)
            for t in range(_around(q, nx, ny, nz, cells, offset2)):
                r = cells[t]
                lr = layer[r]
                if offset2[t] >= 2 and 0 <= lr < L:
                    bt, best = _closer(px, py, pz, T, tri[r], bt, best)
        if best <= descend2:
            bt, best = _descend(px, py, pz, T, nptr, nidx, bt, best)
        tri[q] = bt
        dist2[q] = best


@njit(cache=True)
def _next_layer(front, L, nx, ny, nz, layer, dist2, limit2):
    """The unvisited neighbours of the voxels of ``front`` within the limit, marked layer L."""
    nxt = np.empty(min(26 * len(front), nx * ny * nz), np.int64)
    m = 0
    cells, offset2 = np.empty(27, np.int64), np.empty(27, np.int64)
    for s in range(len(front)):
        q = front[s]
        if dist2[q] > limit2:
            continue
        for t in range(_around(q, nx, ny, nz, cells, offset2)):
            r = cells[t]
            if layer[r] < 0:
                layer[r] = L
                nxt[m] = r
                m += 1
    return nxt[:m].copy()


def _band(T, nptr, nidx, origin, h, shape, limit2, descend2):
    """The propagation: (where, dist2, tri) of every voxel reached, layer by layer; voxels
    are reached while a neighbour is within ``sqrt(limit2)``."""
    nx, ny, nz = shape
    n = nx * ny * nz
    layer = np.full(n, -1, np.int32)
    tri = np.full(n, -1, np.int64)
    dist2 = np.empty(n, np.float64)
    front = _seeds(T, origin, h, nx, ny, nz, layer, tri, dist2)
    visited = []
    L = 0
    while len(front):
        _solve_layer(front, L, T, nptr, nidx, origin, h, nx, ny, nz, layer, tri, dist2, descend2)
        visited.append(front)
        L += 1
        front = _next_layer(front, L, nx, ny, nz, layer, dist2, limit2)
    where = np.concatenate(visited)
    return where, dist2[where], tri[where]


SPREAD = 2.0  # a closest point moving this many times the voxel step marks a possible local minimum
RELAX_ROUNDS = 8  # the relaxation settles in 2-3 rounds (measured); this bounds it


class MeshDistance:
    """Exact distances from the voxels of grids to one triangle mesh.

    Parameters
    ----------
    vertices : (v, 3) float, faces : (f, 3) int

    Notes
    -----
    :meth:`band` propagates closest triangles outward (module docstring), then makes them
    exact where the propagation can be wrong: where two fronts meet, or in a concave pocket
    whose closest triangle is no neighbour's. Both show as a closest point that jumps between
    neighbouring voxels (a smooth surface moves it at most ``R / (R - d)`` times the step, on
    its concave side at distance d from curvature radius R). Those voxels and their
    neighbours are relaxed (every neighbour's triangle tried, then the descent) until nothing
    changes; the voxels still jumping within the exact zone (a few percent of them, near
    medial surfaces) are asked of :class:`.tree.TriangleTree`, bounded by the distance
    they have: exact, and cheap because the bound is tight.

    On a triangle set whose parts overlap or intersect (surfaces left by
    :func:`repair.repair_surface`), a part's Voronoi region can be thinner than a voxel
    and reached by no neighbour without a jump to show it: on three overlapping boxes 2 %
    of the zone's voxels were up to h/2 too far (``tests/test_closest.py`` tests closed
    meshes only).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        V = np.ascontiguousarray(vertices, dtype=np.float64)
        self._F, self._n_vertices = np.ascontiguousarray(faces, dtype=np.int64), len(V)
        a = V[self._F[:, 0]]
        self.T = np.ascontiguousarray(np.hstack([a, V[self._F[:, 1]] - a, V[self._F[:, 2]] - a]))
        self._neighbours = None
        self.tree = TriangleTree(self.T)

    @property
    def neighbours(self) -> tuple[np.ndarray, np.ndarray]:
        """CSR (ptr, idx) of the faces sharing a vertex with each face (the descent's steps)."""
        if self._neighbours is None:
            self._neighbours = _face_neighbours(self._F, self._n_vertices)
        return self._neighbours

    def nearest(self, points: np.ndarray, bound: float = np.inf) -> np.ndarray:
        """(n,) exact distance from each of the points (n, 3) to the mesh, or ``bound`` where
        the mesh is no nearer than that (:class:`.tree.TriangleTree`)."""
        return np.sqrt(self.tree.closest(points, float(bound) ** 2)[1])

    def band(self, origin: np.ndarray, h: float, shape: tuple[int, int, int], limit: float,
             exact: float) -> tuple[np.ndarray, np.ndarray]:
        """Every voxel within ``limit`` of the mesh, with its squared distance.

        Parameters
        ----------
        origin : (3,) centre of voxel (0, 0, 0); h : spacing; shape : (nx, ny, nz)
        limit : distance up to which every voxel is found (some up to a voxel beyond it too)
        exact : distance within which every value is exact; beyond, a value may exceed the
            distance where the propagation went wrong (rare, near medial surfaces)

        Returns
        -------
        where : (b,) int64 flat (C-order) voxel indices, each once
        dist2 : (b,) float64 squared distance to the mesh
        """
        origin = np.asarray(origin, np.float64)
        nx, ny, nz = (int(n) for n in shape)
        h = float(h)
        exact2 = float(exact) ** 2
        nptr, nidx = self.neighbours
        # beyond the zone, the best of the neighbours' triangles, without the descent
        where, dist2, tri = _band(self.T, nptr, nidx, origin, h, (nx, ny, nz), float(limit) ** 2,
                                  (float(exact) + 2.0 * h) ** 2)
        pos = np.full(nx * ny * nz, -1, np.int64)
        pos[where] = np.arange(len(where))
        every = np.arange(len(where))
        foot = np.empty((len(where), 3))
        _feet(where, every, self.T, tri, origin, h, ny, nz, foot)
        flag = _jumps(where, every, foot, dist2, h, nx, ny, nz, pos, exact2, SPREAD)
        sel = _dilate(np.flatnonzero(flag), where, nx, ny, nz, pos)
        # a voxel none of whose neighbours changed keeps its triangle in the next round: each
        # round relaxes the voxels of sel around the last round's changes
        active, moved = sel, []
        for _ in range(RELAX_ROUNDS):
            new_tri, new_dist2 = tri.copy(), dist2.copy()
            _relax(where, active, self.T, nptr, nidx, tri, dist2, origin, h, nx, ny, nz, pos, new_tri, new_dist2)
            changed = active[new_tri[active] != tri[active]]
            tri, dist2 = new_tri, new_dist2
            if len(changed) == 0:
                break
            moved.append(changed)
            active = np.intersect1d(_dilate(changed, where, nx, ny, nz, pos), sel, assume_unique=True)
        if moved:  # the flags can change only where a closest point moved, and beside it
            moved = np.unique(np.concatenate(moved))
            _feet(where, moved, self.T, tri, origin, h, ny, nz, foot)
            near = _dilate(moved, where, nx, ny, nz, pos)
            flag[near] = _jumps(where, near, foot, dist2, h, nx, ny, nz, pos, exact2, SPREAD)
        if flag.any():  # the tree's query, bounded by the propagated distance: exact
            asked = where[flag]
            ijk = np.column_stack(np.unravel_index(asked, (nx, ny, nz)))
            dist2[flag] = self.tree.closest(origin + h * ijk, dist2[flag])[1]
        return where, dist2
