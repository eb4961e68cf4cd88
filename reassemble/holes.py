"""Holes of open scans: boundary loops and their filling, so the surface bounds a solid.

The integral invariants need inside and outside (the occupancy of a ball). A scan missing
the underside of an object, or a fragment scanned from one side and not turned over, has
holes; each hole is closed by a patch spanning its boundary loop: an ear-clipping
triangulation of the loop projected onto its best-fitting plane, or, where that
projection folds over itself, a fan around the loop's centroid. The patch is new surface,
not scanned: it is smooth (flat) and is labelled like the original surface.
"""

from __future__ import annotations

import numpy as np

EAR_CLIP_MAX = 2000  # loops longer than this get the fan (ear clipping is quadratic)


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Closed loops of boundary edges (edges of exactly one face).

    Parameters
    ----------
    faces : (f, 3) int, consistently oriented

    Returns
    -------
    list of (k,) int vertex indices, each loop ordered against the faces' orientation (the
    order a filling face takes them in) and simple: where a hole's outline touches itself
    at a vertex it is split there
    """
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = np.sort(directed, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    boundary = directed[counts[inverse.ravel()] == 1][:, ::-1]  # the hole's side runs the other way
    outgoing: dict[int, list[int]] = {}
    for a, b in boundary:
        outgoing.setdefault(int(a), []).append(int(b))
    loops = []
    for start in sorted(outgoing):
        while outgoing.get(start):
            walk, at, v = [start], {start: 0}, start
            while outgoing.get(v):
                v = outgoing[v].pop()
                if v in at:  # back at a vertex of this walk: a loop closed there
                    k = at[v]
                    if len(walk) - k >= 3:
                        loops.append(np.array(walk[k:], dtype=np.int64))
                    for u in walk[k + 1:]:
                        del at[u]
                    del walk[k + 1:]
                else:
                    at[v] = len(walk)
                    walk.append(v)
    return loops


def _turn(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """z of (b − a) × (c − a), broadcast over leading axes of 2-d points: > 0 turns left."""
    return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])


def _ear_clip(points: np.ndarray) -> list[tuple[int, int, int]] | None:
    """Triangles (indices into ``points``, (k, 2), counter-clockwise) of a simple polygon, or None."""
    ring = np.arange(len(points))
    tris = []
    while len(ring) > 3:
        p = points[ring]
        prev, nxt = np.roll(p, 1, axis=0), np.roll(p, -1, axis=0)
        n = len(ring)
        for k in np.flatnonzero(_turn(prev, p, nxt) > 0):  # reflex and flat corners are no ears
            others = np.delete(p, [(k - 1) % n, k, (k + 1) % n], axis=0)
            a, b, c = prev[k], p[k], nxt[k]
            if np.any((_turn(a, b, others) >= 0) & (_turn(b, c, others) >= 0) & (_turn(c, a, others) >= 0)):
                continue
            tris.append((int(ring[(k - 1) % n]), int(ring[k]), int(ring[(k + 1) % n])))
            ring = np.delete(ring, k)
            break
        else:  # no ear: not a simple polygon after all
            return None
    tris.append(tuple(int(q) for q in ring))
    return tris


def _self_crossing(points: np.ndarray) -> bool:
    """Whether the closed polygon ``points`` (k, 2) crosses itself."""
    k = len(points)
    a, b = points, np.roll(points, -1, axis=0)
    for i in range(k - 2):
        j = np.arange(i + 2, k if i > 0 else k - 1)  # the edges not next to edge i
        if len(j) and np.any((_turn(a[i], b[i], a[j]) * _turn(a[i], b[i], b[j]) < 0)
                             & (_turn(a[j], b[j], a[i]) * _turn(a[j], b[j], b[i]) < 0)):
            return True
    return False


def fill_loop(vertices: np.ndarray, loop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A patch closing one boundary loop.

    Parameters
    ----------
    vertices : (n, 3)
    loop : (k,) vertex indices, in the order :func:`boundary_loops` gives

    Returns
    -------
    new_vertices : (0, 3) or (1, 3) the centroid, when a fan is used (index n)
    new_faces : (k − 2, 3) or (k, 3) int
    """
    p = vertices[loop]
    centre = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - centre, full_matrices=False)
    flat = (p - centre) @ vt[:2].T
    x, y = flat[:, 0], flat[:, 1]
    ccw = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0
    if not ccw:
        flat = flat * np.array([1.0, -1.0])  # mirror so the loop runs counter-clockwise
    if len(loop) <= EAR_CLIP_MAX and not _self_crossing(flat):
        tris = _ear_clip(flat)
        if tris is not None:
            return np.zeros((0, 3)), loop[np.asarray(tris, dtype=np.int64)]
    k = len(loop)
    fan = np.column_stack([loop, np.roll(loop, -1), np.full(k, len(vertices))])
    return centre[None], fan


def fill_holes(
    vertices: np.ndarray, faces: np.ndarray, *, max_size: float
) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """Close every hole whose extent is at most ``max_size`` of the mesh's diagonal.

    Parameters
    ----------
    vertices : (n, 3)
    faces : (f, 3) int, consistently oriented
    max_size : largest hole filled: the diagonal of the loop's bounding box over the
        mesh's, a fraction

    Returns
    -------
    vertices : (n', 3) with a centroid per fan-filled hole appended (inputs are not modified)
    faces : (f', 3) the faces with the patches appended
    sizes : the extent of every hole found, a fraction of the diagonal, largest first; those
        above ``max_size`` are left open
    """
    diag = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    new_v, new_f, sizes = [np.asarray(vertices, float)], [np.asarray(faces, np.int64)], []
    n = len(vertices)
    for loop in boundary_loops(faces):
        size = float(np.linalg.norm(np.ptp(vertices[loop], axis=0))) / diag
        sizes.append(size)
        if size > max_size:
            continue
        extra, tris = fill_loop(vertices, loop)
        if len(extra):
            tris = np.where(tris == len(vertices), n, tris)
            new_v.append(extra)
            n += len(extra)
        new_f.append(tris)
    return np.vstack(new_v), np.vstack(new_f), sorted(sizes, reverse=True)


__all__ = ["boundary_loops", "fill_holes", "fill_loop"]
