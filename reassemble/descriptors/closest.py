"""Distances to a triangle mesh in a band of grid voxels, by closest-triangle propagation.

Layer 0 is the voxels nearest points spread over every triangle at most a voxel apart,
each with the closest of the triangles that marked it. The band then grows outward layer
by layer (26 neighbours). A voxel starts from the closest triangles of its face neighbours
of earlier layers and descends on the mesh: it moves to any triangle sharing a vertex with
the current one that is closer, until none is. A step costs a dozen exact point-triangle
distances and the start is within about a voxel of the answer, so a voxel costs a few
dozen distances whatever the mesh's size, where a tree query (Open3D, libigl's AABB) costs
7-19 us and slows down with the distance from the surface.

The descent finds the closest triangle wherever the distance over the mesh has one minimum
near the start. Where it has several (two fronts meeting, concave pockets),
:class:`MeshDistance` finds the voxels that may be wrong and makes them exact (its Notes).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

# TBB, numba's first choice, warns when the system's is too old; OpenMP ships with numba
numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]


@njit(cache=True, inline="always")
def _tri_dist2(px, py, pz, T, t):
    """Squared distance from p to triangle t, whose row of T is (a, b - a, c - a)
    (Ericson, Real-Time Collision Detection, 5.1.5)."""
    ax, ay, az = T[t, 0], T[t, 1], T[t, 2]
    abx, aby, abz = T[t, 3], T[t, 4], T[t, 5]
    acx, acy, acz = T[t, 6], T[t, 7], T[t, 8]
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return apx * apx + apy * apy + apz * apz
    bpx, bpy, bpz = apx - abx, apy - aby, apz - abz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bpx * bpx + bpy * bpy + bpz * bpz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        qx, qy, qz = apx - v * abx, apy - v * aby, apz - v * abz
        return qx * qx + qy * qy + qz * qz
    cpx, cpy, cpz = apx - acx, apy - acy, apz - acz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cpx * cpx + cpy * cpy + cpz * cpz
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        qx, qy, qz = apx - w * acx, apy - w * acy, apz - w * acz
        return qx * qx + qy * qy + qz * qz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        qx = bpx - w * (acx - abx)
        qy = bpy - w * (acy - aby)
        qz = bpz - w * (acz - abz)
        return qx * qx + qy * qy + qz * qz
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    qx = apx - abx * v - acx * w
    qy = apy - aby * v - acy * w
    qz = apz - abz * v - acz * w
    return qx * qx + qy * qy + qz * qz


@njit(cache=True, inline="always")
def _tri_closest(px, py, pz, T, t):
    """The point of triangle t closest to p (same regions as :func:`_tri_dist2`)."""
    ax, ay, az = T[t, 0], T[t, 1], T[t, 2]
    abx, aby, abz = T[t, 3], T[t, 4], T[t, 5]
    acx, acy, acz = T[t, 6], T[t, 7], T[t, 8]
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az
    bpx, bpy, bpz = apx - abx, apy - aby, apz - abz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return ax + abx, ay + aby, az + abz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return ax + v * abx, ay + v * aby, az + v * abz
    cpx, cpy, cpz = apx - acx, apy - acy, apz - acz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return ax + acx, ay + acy, az + acz
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return ax + w * acx, ay + w * acy, az + w * acz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return ax + abx + w * (acx - abx), ay + aby + w * (acy - aby), az + abz + w * (acz - abz)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w


@njit(cache=True, inline="always")
def _closer(px, py, pz, T, g, bt, best):
    """(triangle, squared distance): ``g`` where it is closer to the point than ``best``
    (that of triangle ``bt``), else ``bt``, ``best``."""
    if g != bt:
        d = _tri_dist2(px, py, pz, T, g)
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
def _suspects(where, T, tri, dist2, origin, h, nx, ny, nz, pos, exact2, spread):
    """Voxels within the exact zone whose closest point moves more than ``spread`` times as
    far as the voxel does, to some neighbour's: where descents may stop at a local minimum."""
    b = len(where)
    foot = np.empty((b, 3))
    for s in prange(b):
        q = where[s]
        k = q % nz
        j = (q // nz) % ny
        i = q // (ny * nz)
        foot[s, 0], foot[s, 1], foot[s, 2] = _tri_closest(origin[0] + h * i, origin[1] + h * j,
                                                          origin[2] + h * k, T, tri[s])
    flag = np.zeros(b, np.bool_)
    s2 = spread * spread
    for s in prange(b):
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
                flag[s] = True
    return flag


@njit(cache=True, parallel=True)
def _relax(where, sel, T, nptr, nidx, tri, dist2, origin, h, nx, ny, nz, pos, new_tri, new_dist2):
    """For the voxels ``sel`` (positions in ``where``): the best of every neighbour's closest
    triangle, then the descent; written to new_tri, new_dist2. Returns how many improved."""
    changed = 0
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
            changed += 1
        new_tri[s] = bt
        new_dist2[s] = best
    return changed


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
def _dist2_to(where, tri, T, origin, h, ny, nz):
    """(k,) squared distance from each voxel of ``where`` (flat indices) to its triangle ``tri``."""
    out = np.empty(len(where))
    for s in range(len(where)):
        q = where[s]
        k = q % nz
        j = (q // nz) % ny
        i = q // (ny * nz)
        out[s] = _tri_dist2(origin[0] + h * i, origin[1] + h * j, origin[2] + h * k, T, tri[s])
    return out


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
            d = _tri_dist2(px, py, pz, T, g)
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
                d = _tri_dist2(origin[0] + h * i, origin[1] + h * j, origin[2] + h * k, T, t)
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
            best = _tri_dist2(px, py, pz, T, bt)
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
    changes; the voxels still jumping within the exact zone are asked of ``fallback``, an
    exact tree query (a few percent of the voxels, near medial surfaces).

    On a triangle set whose parts overlap or intersect (surfaces left by
    :func:`repair.repair_surface`), a part's Voronoi region can be thinner than a voxel
    and reached by no neighbour without a jump to show it: on three overlapping boxes 2 %
    of the zone's voxels were up to h/2 too far (``tests/test_closest.py`` tests closed
    meshes only).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        V = np.ascontiguousarray(vertices, dtype=np.float64)
        F = np.ascontiguousarray(faces, dtype=np.int64)
        self.nptr, self.nidx = _face_neighbours(F, len(V))
        a = V[F[:, 0]]
        self.T = np.ascontiguousarray(np.hstack([a, V[F[:, 1]] - a, V[F[:, 2]] - a]))

    def band(self, origin: np.ndarray, h: float, shape: tuple[int, int, int], limit: float,
             exact: float, fallback=None) -> tuple[np.ndarray, np.ndarray]:
        """Every voxel within ``limit`` of the mesh, with its squared distance.

        Parameters
        ----------
        origin : (3,) centre of voxel (0, 0, 0); h : spacing; shape : (nx, ny, nz)
        limit : distance up to which every voxel is found (some up to a voxel beyond it too)
        exact : distance within which every value is exact; beyond, a value may exceed the
            distance where the propagation went wrong (rare, near medial surfaces)
        fallback : callable, flat voxel indices (k,) -> (k,) index of a closest face (an
            exact query, in any precision: the distance is then computed here in float64);
            None: the voxels it would be asked for keep their propagated values

        Returns
        -------
        where : (b,) int64 flat (C-order) voxel indices, each once
        dist2 : (b,) float64 squared distance to the mesh
        """
        origin = np.asarray(origin, np.float64)
        nx, ny, nz = (int(n) for n in shape)
        h = float(h)
        exact2 = float(exact) ** 2
        # beyond the zone, the best of the neighbours' triangles, without the descent
        where, dist2, tri = _band(self.T, self.nptr, self.nidx, origin, h, (nx, ny, nz), float(limit) ** 2,
                                  (float(exact) + 2.0 * h) ** 2)
        pos = np.full(nx * ny * nz, -1, np.int64)
        pos[where] = np.arange(len(where))
        flag = _suspects(where, self.T, tri, dist2, origin, h, nx, ny, nz, pos, exact2, SPREAD)
        sel = _dilate(np.flatnonzero(flag), where, nx, ny, nz, pos)
        for _ in range(RELAX_ROUNDS):
            new_tri, new_dist2 = tri.copy(), dist2.copy()
            changed = _relax(where, sel, self.T, self.nptr, self.nidx, tri, dist2, origin, h, nx, ny, nz, pos,
                             new_tri, new_dist2)
            tri, dist2 = new_tri, new_dist2
            if changed == 0:
                break
        if fallback is not None:
            flag = _suspects(where, self.T, tri, dist2, origin, h, nx, ny, nz, pos, exact2, SPREAD)
            if flag.any():
                asked = where[flag]
                d2 = _dist2_to(asked, np.asarray(fallback(asked), np.int64), self.T, origin, h, ny, nz)
                dist2[flag] = np.minimum(dist2[flag], d2)
        return where, dist2
