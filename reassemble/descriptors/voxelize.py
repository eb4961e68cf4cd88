"""Grids for the integral invariants: anti-aliased occupancy and narrow-band squared distance.

Occupancy is a linear ramp of the signed distance across the surface (exact distances in
a thin band from :class:`closest.MeshDistance`'s box hierarchy, the sign from ray parity
along grid columns). Measured on a
sphere, it is 2-4x more accurate than exact partial coverage along axis rays, whose
smoothing depends on the surface orientation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


# Grid origins are shifted by this fraction of a voxel so that axis-aligned faces of CAD
# meshes, whose coordinates are often round numbers, never lie on a ray.
_ORIGIN_JITTER = 0.1234567


@dataclass(frozen=True)
class Grid:
    """A regular grid of voxel centres ``origin + h * (i, j, k)``.

    Attributes
    ----------
    origin : (3,) float, centre of voxel (0, 0, 0)
    h : voxel edge length
    shape : (nx, ny, nz)
    """

    origin: np.ndarray
    h: float
    shape: tuple[int, int, int]

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def axis(self, a: int) -> np.ndarray:
        return self.origin[a] + self.h * np.arange(self.shape[a])


def make_grid(bbox_min: np.ndarray, bbox_max: np.ndarray, *, h: float, margin: float) -> Grid:
    """Grid of spacing ``h`` covering the box plus ``margin``, with FFT-friendly sizes."""
    from scipy.fft import next_fast_len

    lo = np.asarray(bbox_min, float) - margin
    extent = np.asarray(bbox_max, float) + margin - lo
    shape = tuple(int(next_fast_len(int(np.ceil(e / h)) + 2, real=True)) for e in extent)
    centre = lo + extent / 2
    origin = centre - h * (np.array(shape) - 1) / 2 + _ORIGIN_JITTER * h
    return Grid(origin=origin, h=float(h), shape=shape)


def inside_centres(scene, grid: Grid, *, ray_start: np.ndarray | None = None) -> np.ndarray:
    """Whether each voxel centre is inside the closed mesh: ray parity, one ray per column.

    Rays run along z; columns where the ray meets the surface an odd number of times
    (it grazed an edge) are decided by rays along x instead, then y. They start a voxel
    before the grid, or at ``ray_start`` (3,) where that is lower: a grid that is a tile
    of a larger one may begin inside the solid, and parity counts from outside.
    """
    import open3d as o3d

    inside = np.zeros(grid.shape, bool)
    undecided = np.ones(grid.shape[:2] + (1,), bool)  # per column of the first pass
    for axis in (2, 0, 1):
        a, b = [i for i in range(3) if i != axis]
        ua, ub = np.meshgrid(grid.axis(a), grid.axis(b), indexing="ij")
        start = _ray_start(grid, axis, ray_start)
        rays = np.zeros((ua.size, 6), np.float32)
        rays[:, a], rays[:, b], rays[:, axis] = ua.ravel(), ub.ravel(), start
        rays[:, 3 + axis] = 1.0
        hits = scene.list_intersections(o3d.core.Tensor(rays))
        ray_ids = hits["ray_ids"].numpy().astype(np.int64)
        t = hits["t_hit"].numpy().astype(np.float64)
        order = np.lexsort((t, ray_ids))
        ray_ids, t = ray_ids[order], t[order]
        # a ray through an edge or vertex is reported once per triangle there: one crossing
        dup = np.zeros(len(t), bool)
        dup[1:] = (ray_ids[1:] == ray_ids[:-1]) & (t[1:] - t[:-1] < 1e-4 * grid.h)
        ray_ids, t = ray_ids[~dup], t[~dup]
        counts = np.bincount(ray_ids, minlength=ua.size)
        good = counts % 2 == 0
        keep = good[ray_ids]
        ray_ids, t = ray_ids[keep], t[keep]
        n = grid.shape[axis]
        # centre k (at k in voxel units) is inside when enter <= k < leave
        u = (t + start - grid.origin[axis]) / grid.h
        k_in = np.clip(np.ceil(u[0::2]), 0, n).astype(np.int64)
        k_out = np.clip(np.ceil(u[1::2]), 0, n).astype(np.int64)
        rid = ray_ids[0::2]
        diff = np.zeros((ua.size, n + 1), np.int8)  # intervals never overlap: values stay 0/1
        np.add.at(diff, (rid, k_in), 1)
        np.add.at(diff, (rid, k_out), -1)
        column = np.cumsum(diff[:, :n], axis=1, dtype=np.int8) > 0
        perm = np.argsort([a, b, axis])
        column = np.transpose(column.reshape(grid.shape[a], grid.shape[b], n), perm)
        good = np.transpose(np.broadcast_to(good.reshape(grid.shape[a], grid.shape[b], 1),
                                            (grid.shape[a], grid.shape[b], n)), perm)
        if axis == 2:
            inside = column.copy()
            undecided = ~good
        else:
            take = undecided & good
            inside[take] = column[take]
            undecided &= ~good
        if not undecided.any():
            break
    return inside


def _ray_start(grid: Grid, axis: int, ray_start: np.ndarray | None) -> float:
    """Where rays along ``axis`` start: a voxel before the grid, or ``ray_start[axis]`` if lower."""
    start = grid.origin[axis] - grid.h
    return start if ray_start is None else min(start, float(ray_start[axis]))


def _either_side(changes: list[np.ndarray]) -> np.ndarray:
    """(nx, ny, nz) bool: the voxels on either side of a change between neighbours.

    Parameters
    ----------
    changes : per axis a, a bool array one shorter than the grid along a, True where
        voxel i and i + 1 differ
    """
    shape = list(changes[0].shape)
    shape[0] += 1
    boundary = np.zeros(shape, bool)
    for axis, change in enumerate(changes):
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        boundary[tuple(lo)] |= change
        boundary[tuple(hi)] |= change
    return boundary


def occupancy(scene, distance, grid: Grid, *, width: float = 2.0, ray_start: np.ndarray | None = None) -> np.ndarray:
    """Anti-aliased occupancy ``clip(0.5 - sdf / (width h), 0, 1)`` of a closed mesh.

    Exact distances are computed only for voxels near the surface (where the value is
    fractional); the sign comes from ray parity. This equals the mean, over offsets
    t uniform in [-w/2, w/2], of the indicator of the solid grown by t: a symmetric
    smoothing whose small curvature bias (variance w^2/12) is removed analytically
    downstream. ``distance``: the mesh's :class:`closest.MeshDistance`. ``ray_start``: as
    :func:`inside_centres`.

    Returns
    -------
    (nx, ny, nz) float32
    """
    from scipy.ndimage import binary_dilation

    inside = inside_centres(scene, grid, ray_start=ray_start)
    boundary = _either_side([np.diff(inside, axis=axis) for axis in range(3)])
    # boundary voxels lie within one step of the surface; the ramp reaches width/2 beyond
    band = binary_dilation(boundary, iterations=max(1, int(np.ceil(width / 2))))
    where = np.flatnonzero(band)
    d = _ramp_distances(distance, grid, where, 0.5 * width * grid.h)
    sdf = np.where(inside.ravel()[where], -d, d)
    occ = inside.astype(np.float32).ravel()
    occ[where] = np.clip(0.5 - sdf / (width * grid.h), 0.0, 1.0)
    return occ.reshape(grid.shape)


def winding_occupancy(scene, vertices: np.ndarray, faces: np.ndarray, grid: Grid, *,
                      width: float = 2.0, winding=None, distance=None, ray_start: np.ndarray | None = None,
                      frame=None) -> np.ndarray:
    """Anti-aliased occupancy of any triangle set, from its generalized winding number.

    The same ramp as :func:`occupancy`, ``clip(0.5 - sdf / (width h), 0, 1)``, with the
    distance to the triangles and the side from the winding number ``w`` (inside where
    ``w >= 1/2``); beyond the ramp, ``clip(w, 0, 1)``: 1 where shells overlap, a smooth
    transition across holes. ``winding``: the set's :class:`repair.WindingNumber`, when the
    caller evaluates several grids of it (built here otherwise); ``distance``: its
    :class:`closest.MeshDistance`, likewise. ``ray_start``: where the
    column rays start, as :func:`inside_centres` (the running sum counts from there).
    ``frame``: for a tile of a larger grid spanning all of its z, (offset (3,) int of the
    tile in it, its shape): the columns checked are those the larger grid checks, so the
    tile's values are the larger grid's but within ``COARSE`` voxels of its x and y sides.

    Notes
    -----
    Evaluating ``w`` at every voxel would cost a hierarchical sum per voxel. Along a ray
    it jumps by exactly +1 where the ray enters through a face (against its normal) and
    -1 where it leaves, and between crossings it changes only near holes. So one ray per
    grid column gives ``w`` as the running sum of the signed crossings, exact for any
    closed triangle set (non-manifold, overlapping, folded), and ``w`` itself (libigl's
    fast winding number) is evaluated only in the columns where that sum can be wrong:
    those whose crossings do not sum to zero (through a hole, or past an unseen crossing)
    and those next to a point of a coarse lattice (every ``COARSE`` voxels) where it
    disagrees with ``w`` by more than ``LATTICE_TOL`` (through two holes, or beside one).
    There ``w`` is read at both ends and the middle of every stretch between crossings:
    constant where they agree, else every ``STRIDE`` voxels and linearly between.

    Returns
    -------
    (nx, ny, nz) float32
    """
    from scipy.ndimage import binary_dilation

    from ..repair import WindingNumber
    from .closest import MeshDistance

    vertices = np.asarray(vertices, np.float64)
    winding = winding or WindingNumber(vertices, faces)
    nx, ny, nz = grid.shape
    ray_ids, k, sign = _column_crossings(scene, vertices, faces, grid, ray_start=ray_start)
    diff = np.zeros((nx * ny, nz + 1), np.int16)  # |w| <= the faces a column crosses
    np.add.at(diff, (ray_ids, k), sign)
    w = np.cumsum(diff[:, :nz], axis=1, dtype=np.int16).astype(np.float32)  # (columns, nz)
    suspect = np.bincount(ray_ids, sign, nx * ny) != 0
    suspect |= _lattice_disagrees(w, grid, winding, frame)
    if suspect.any():
        _exact_columns(w, np.flatnonzero(suspect), ray_ids, k, grid, winding)
    w = w.reshape(grid.shape)
    inside = w >= 0.5
    # a jump of w between neighbours is a surface; across a hole it changes smoothly,
    # and no distance is needed there (the ramp would be flat)
    boundary = _either_side([np.abs(np.diff(w, axis=axis)) > 0.5 for axis in range(3)])
    # the voxels either side of every crossing: open sheets whose two sides read alike too
    inner = (k > 0) & (k < nz)
    col_i, col_j = np.unravel_index(ray_ids[inner], (nx, ny))
    boundary[col_i, col_j, k[inner]] = True
    boundary[col_i, col_j, k[inner] - 1] = True
    band = binary_dilation(boundary, iterations=max(1, int(np.ceil(width / 2))))
    where = np.flatnonzero(band)
    d = _ramp_distances(distance or MeshDistance(vertices, faces), grid, where, 0.5 * width * grid.h)
    ramp = np.clip(0.5 - np.where(inside.ravel()[where], -d, d) / (width * grid.h), 0.0, 1.0)
    occ = np.clip(w, 0.0, 1.0).ravel()
    near_surface = d < 0.5 * width * grid.h
    occ[where[near_surface]] = ramp[near_surface]
    return occ.reshape(grid.shape)


def _column_crossings(scene, vertices: np.ndarray, faces: np.ndarray, grid: Grid, *,
                      ray_start: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where one ray per grid column (along z) crosses the triangles, and which way.

    Parameters
    ----------
    scene : ray-casting scene of the triangles
    vertices : (n, 3) float64, faces : (m, 3) int
    grid : Grid
    ray_start : (3,) or None, as :func:`inside_centres`

    Returns
    -------
    ray_ids : (c,) int64, the column (``i * ny + j``) of each crossing, ascending
    k : (c,) int64, the first voxel centre past the crossing (0 ... nz)
    sign : (c,) int64, +1 entering (against the face's normal), -1 leaving, 0 grazing
    """
    import open3d as o3d

    ua, ub = np.meshgrid(grid.axis(0), grid.axis(1), indexing="ij")
    start = _ray_start(grid, 2, ray_start)
    rays = np.zeros((ua.size, 6), np.float32)
    rays[:, 0], rays[:, 1], rays[:, 2], rays[:, 5] = ua.ravel(), ub.ravel(), start, 1.0
    hits = scene.list_intersections(o3d.core.Tensor(rays))
    ray_ids = hits["ray_ids"].numpy().astype(np.int64)
    t = hits["t_hit"].numpy().astype(np.float64)
    prim = hits["primitive_ids"].numpy().astype(np.int64)
    tri = vertices[np.asarray(faces)[prim]]
    nz_normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 2]
    sign = np.where(nz_normal < 0, 1, -1).astype(np.int64)  # entering against the normal: +1
    sign[nz_normal == 0] = 0  # grazing a face edge-on: no crossing
    order = np.lexsort((sign, t, ray_ids))
    ray_ids, t, sign = ray_ids[order], t[order], sign[order]
    # a ray through an edge or vertex is reported once per triangle there: one crossing
    # (faces meeting there in opposite orientations, as walls between cells, both count)
    dup = np.zeros(len(t), bool)
    dup[1:] = (ray_ids[1:] == ray_ids[:-1]) & (t[1:] - t[:-1] < 1e-4 * grid.h) & (sign[1:] == sign[:-1])
    ray_ids, t, sign = ray_ids[~dup], t[~dup], sign[~dup]
    u = (t + start - grid.origin[2]) / grid.h
    k = np.clip(np.ceil(u), 0, grid.shape[2]).astype(np.int64)
    return ray_ids, k, sign


def _lattice(n: int, offset: int, frame: int) -> tuple[np.ndarray, np.ndarray]:
    """The coarse lattice along one axis of ``n`` voxels that start at ``offset`` in a frame
    of ``frame`` voxels: every ``COARSE``-th voxel of the frame and its last, in the axis's
    indices (some outside ``[0, n)``), and which of them are inside."""
    at = np.unique(np.r_[np.arange(0, frame, COARSE), frame - 1]) - offset
    return at, (at >= 0) & (at < n)


def _lattice_disagrees(w: np.ndarray, grid: Grid, winding, frame=None) -> np.ndarray:
    """(nx * ny,) bool: the columns near a point of the coarse lattice (every ``COARSE``
    voxels) where the running sum ``w`` (columns, nz) is off the exact winding number by
    more than ``LATTICE_TOL`` (what the running sum cannot see: through two holes, or
    beside one). ``frame``: (offset (3,) int, shape) of the grid this one is a tile of,
    whose lattice is used, so that a tile flags the columns the whole grid does but within
    ``COARSE`` voxels of its sides."""
    nx, ny, _ = grid.shape
    offset, shape = frame if frame is not None else ((0, 0, 0), grid.shape)
    (li, ini), (lj, inj), (lk, ink) = (_lattice(n, o, f) for n, o, f in zip(grid.shape, offset, shape))
    ci, cj, ck = li[ini], lj[inj], lk[ink]
    I, J, K = np.meshgrid(ci, cj, ck, indexing="ij")
    wl = winding(grid.origin + grid.h * np.column_stack([I.ravel(), J.ravel(), K.ravel()]))
    bad = (np.abs(wl - w.reshape(grid.shape)[I.ravel(), J.ravel(), K.ravel()]) > LATTICE_TOL).reshape(I.shape)
    bad = bad.any(axis=2)
    pi, pj = np.flatnonzero(ini), np.flatnonzero(inj)  # lattice positions of the evaluated points
    near = np.zeros((nx, ny), bool)  # the columns of every lattice cell with a bad corner
    for a, b in zip(*np.nonzero(bad)):
        a, b = pi[a], pj[b]
        i0, i1 = max(li[max(a - 1, 0)], 0), li[min(a + 1, len(li) - 1)] + 1
        j0, j1 = max(lj[max(b - 1, 0)], 0), lj[min(b + 1, len(lj) - 1)] + 1
        near[i0:i1, j0:j1] = True
    return near.ravel()


COARSE = 8  # lattice step (voxels) of the exact winding numbers that check the running sum
LATTICE_TOL = 0.25  # ... a lattice point further than this from the sum marks its columns
STRIDE = 8  # in a column's stretch where w varies, exact every this many voxels, linear between
CONSTANT = 0.02  # a stretch whose ends and middle agree this well is constant


def _exact_columns(w: np.ndarray, columns: np.ndarray, ray_ids: np.ndarray, k: np.ndarray, grid: Grid,
                   winding) -> None:
    """Replace, in place, the running sum ``w`` (columns, nz) of the given columns by the
    winding number: per stretch between crossings, the exact value at both ends and the
    middle, and where these differ, every ``STRIDE`` voxels with linear interpolation."""
    nx, ny, nz = grid.shape
    cuts = np.zeros((len(columns), nz + 1), bool)
    row = np.full(nx * ny, -1)
    row[columns] = np.arange(len(columns))
    sel = row[ray_ids] >= 0
    cuts[row[ray_ids[sel]], k[sel]] = True
    cuts[:, 0] = cuts[:, nz] = True
    r, a = np.nonzero(cuts[:, :nz])  # stretch starts, in row order
    nxt = np.flatnonzero(cuts.ravel())
    ends = nxt[1:][np.diff(nxt // (nz + 1)) == 0] % (nz + 1)  # the next cut in the same row
    keep = ends > a
    r, a, b = r[keep], a[keep], ends[keep]
    i, j = np.unravel_index(columns[r], (nx, ny))
    mid = (a + b - 1) // 2

    def at(ii, jj, kk):
        return winding(grid.origin + grid.h * np.column_stack([ii, jj, kk]))

    sample = at(np.r_[i, i, i], np.r_[j, j, j], np.r_[a, mid, b - 1]).reshape(3, -1)
    constant = np.ptp(sample, axis=0) <= CONSTANT
    # every voxel's stretch
    starts = np.zeros((len(columns), nz), bool)
    starts[r, a] = True
    sid = np.cumsum(starts.ravel()) - 1  # stretches are numbered in row-major order of their starts
    stretch = sid.reshape(len(columns), nz)
    rows_of = np.broadcast_to(np.arange(len(columns))[:, None], stretch.shape)
    valid = rows_of == r[stretch]  # voxels before a row's first cut belong to no stretch
    block = w[columns]
    cst = valid & constant[stretch]
    block[cst] = sample[1][stretch[cst]]
    var = valid & ~constant[stretch]
    if var.any():
        rr, xx = np.nonzero(var)  # the varying voxels only: the block can be millions
        st = stretch[rr, xx]
        s0, s1 = a[st], b[st] - 1
        on = ((xx - s0) % STRIDE == 0) | (xx == s1)
        exact = np.full(block.shape, np.nan)
        exact[rr[on], xx[on]] = at(i[st[on]], j[st[on]], xx[on])
        lo = s0 + ((xx - s0) // STRIDE) * STRIDE
        hi = np.minimum(lo + STRIDE, s1)
        wt = (xx - lo) / np.maximum(hi - lo, 1)
        block[rr, xx] = exact[rr, lo] * (1 - wt) + exact[rr, hi] * wt
    w[columns] = block


def saturated_square(d: np.ndarray, r: float, band: float) -> np.ndarray:
    """``d**2`` up to ``r``, then a C2 quartic roll-off to a constant at ``band``.

    Integrals over balls of radius r around surface points see only ``d <= r``, so the
    roll-off changes nothing exact; it only keeps the field smooth where a plain clamp
    would leave a kink whose Gibbs ringing (measured on a sphere: 2.5x the K2 noise at
    band = r + 3h) leaks into every ball through the band-limited kernel.
    """
    d = np.asarray(d, dtype=np.float64)
    L = band - r
    u = np.clip((d - r) / L, 0.0, 1.0)
    a = -6.0 * r * L - 4.0 * L * L
    b = 4.0 * r * L + 2.0 * L * L
    tail = r * r + 2 * r * L * u + L * L * u**2 + a * u**3 / 3 + b * u**4 / 4
    return np.where(d <= r, d * d, tail)


def saturated_signed(d: np.ndarray, r: float, band: float) -> np.ndarray:
    """``d`` up to ``|d| = r``, then an odd C2 roll-off to ``±(r + (band - r)/2)`` at ``|d| = band``.

    The signed counterpart of :func:`saturated_square`: with u = (|d| - r)/(band - r), the
    slope 1 - 3u^2 + 2u^3 falls from 1 to 0 with zero curvature at both ends.
    """
    d = np.asarray(d, dtype=np.float64)
    a = np.abs(d)
    L = band - r
    u = np.clip((a - r) / L, 0.0, 1.0)
    tail = r + L * (u - u**3 + 0.5 * u**4)
    return np.where(a <= r, d, np.sign(d) * tail)


def distance_band(distance, grid: Grid, *, r: float, band: float) -> tuple[np.ndarray, np.ndarray]:
    """The voxels within ``band`` of the surface and their squared distances, exact within ``r``
    plus two voxels (:meth:`closest.MeshDistance.band`; the arguments as :func:`squared_distance`).

    Returns
    -------
    where : (b,) int64 flat voxel indices; dist2 : (b,) float64
    """
    return distance.band(grid.origin, grid.h, grid.shape, band, r + 2 * grid.h)


def _ramp_distances(distance, grid: Grid, where: np.ndarray, reach: float) -> np.ndarray:
    """Exact distances to the surface at the voxels with flat indices ``where``, or ``reach``
    where it is farther (:meth:`closest.MeshDistance.nearest`): the ramp is flat beyond."""
    ijk = np.column_stack(np.unravel_index(where, grid.shape))
    return distance.nearest(grid.origin + grid.h * ijk, reach)


def signed_distance(near: tuple[np.ndarray, np.ndarray], inside: np.ndarray, *, r: float, band: float) -> np.ndarray:
    """Signed distance to the surface (> 0 outside) within ``r``, rolled off to ``±c`` at ``band``.

    Parameters
    ----------
    near : (where, dist2) of :func:`distance_band`
    inside : (nx, ny, nz) bool, the voxel centres inside the solid
    r, band : as :func:`squared_distance`

    Returns
    -------
    (nx, ny, nz) float32: :func:`saturated_signed` of the signed distance minus its far
    outside value ``c``: zero outside the band, ``-2c`` inside it.
    """
    where, dist2 = near
    c = float(saturated_signed(np.array(band), r, band))
    out = np.where(inside, np.float32(-2.0 * c), np.float32(0.0)).ravel()
    d = np.sqrt(dist2)
    d[inside.ravel()[where]] *= -1.0
    out[where] = saturated_signed(d, r, band) - c
    return out.reshape(inside.shape)


def squared_distance(distance, grid: Grid, *, r: float, band: float, near=None) -> np.ndarray:
    """Squared distance to the surface within ``r``, rolled off smoothly to a constant at ``band``.

    Parameters
    ----------
    distance : :class:`closest.MeshDistance` of the surface
    grid : Grid
    r : radius within which the distances are exact; band : where the roll-off ends
    near : the result of :func:`distance_band` for these arguments, if already computed

    Returns
    -------
    (nx, ny, nz) float32: :func:`saturated_square` of the distance minus its far value,
    ``saturated_square(band)`` (so float32 FFTs lose nothing to a large constant): zero
    beyond the band.

    Notes
    -----
    Every voxel within ``band`` is computed (those beyond saturate to zero). Within ``r``
    plus two voxels the distances are exact (measured on a sphere: without a voxel of
    overlap, 2x the K2 noise), so the spline through the samples is exact wherever it
    reaches into a ball of radius ``r`` about a surface point. Beyond, in the roll-off,
    where only smoothness matters, they are the propagated ones (a distance to some
    triangle: rarely, near medial surfaces, a little too long).
    """
    far = float(saturated_square(np.array(band), r, band))
    where, dist2 = distance_band(distance, grid, r=r, band=band) if near is None else near
    out = np.zeros(grid.size, np.float32)
    out[where] = saturated_square(np.sqrt(dist2), r, band) - far
    return out.reshape(grid.shape)
