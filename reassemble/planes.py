"""Planar break faces and the placements they give by construction.

A break that is a plane (a clean cut, the cell faces of a Voronoi fracture as in Breaking
Bad) is the same plane region on both fragments, seen from either side: the same area, the
same centroid and the same second moments, with opposed normals. Two such regions fix a
placement up to the in-plane turn, and their principal axes fix that turn up to a half
turn. These placements need no signature: on a plane every point's invariants are the same
(a flat disc), so signature matching gives the registration nothing to go on there, and
vertex noise makes it worse. See ``docs/method/registration.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import make_transform


_LOCAL_SEED_NEIGHBOURS = 12  # a local seed's two other samples: among this many nearest
_MISSES = 8  # planes under ``min_area`` set aside before the search ends


@dataclass(frozen=True)
class PlanarPatch:
    """Fracture samples that lie on one plane.

    Attributes
    ----------
    centre : (3,) area centroid
    normal : (3,) unit normal, outward (the samples' side)
    axes : (2, 3) unit in-plane principal axes, the wider spread first
    spread : (2,) standard deviation of the samples along ``axes``
    area : float, the fracture area on the plane
    flat : (k, 2) the samples in the plane, coordinates along ``axes`` from ``centre``
    """

    centre: np.ndarray
    normal: np.ndarray
    axes: np.ndarray
    spread: np.ndarray
    area: float
    flat: np.ndarray


def planar_patches(
    points: np.ndarray, normals: np.ndarray, sample_area: float, *, tol: float, min_area: float,
    normal_angle: float = 60.0, max_patches: int = 16, seeds: int = 64, rng: np.random.Generator,
) -> list[PlanarPatch]:
    """The planes that carry at least ``min_area`` of the samples, largest first.

    Parameters
    ----------
    points : (q, 3) area-uniform samples of a fracture surface
    normals : (q, 3) unit normals at them
    sample_area : area each sample stands for
    tol : largest distance of a sample from its plane (mesh units: the contact tolerance,
        which covers vertex noise)
    min_area : a plane with less sample area is not reported
    normal_angle : degrees: largest angle between a sample's normal and its plane's (only
        keeps the far side of a thin part and sharp folds out: noisy face normals stray far)
    max_patches : at most this many planes
    seeds : planes through three random samples tried for each patch
    rng : numpy Generator (the seed samples)

    Returns
    -------
    list of PlanarPatch

    Notes
    -----
    RANSAC on planes through three samples (a face normal is too noisy to seed a plane:
    ten degrees off tilts it by a sixth of its width), refitted to its inliers by principal
    components; the inliers leave the pool and the search repeats. All the samples of one
    plane form one patch even when they are apart (a cut through a ring crosses it twice),
    as they do on the mate. Half the seeds are three random samples (wide planes in parts),
    half a sample and two of its neighbours: three random samples fall on one face with
    the cube of its share, two neighbours almost surely on their sample's face, so a small
    face among many (a CAD part, a cell with many faces) is seeded in proportion to its
    share (localised sampling, Schnabel et al. 2007, Computer Graphics Forum 26(2)). A plane
    under ``min_area`` found before a larger one is set aside and the search goes on.
    """
    points, normals = np.asarray(points, float), np.asarray(normals, float)
    cos_tol = np.cos(np.radians(normal_angle))
    free = np.ones(len(points), bool)
    out: list[PlanarPatch] = []
    if len(points) < 3:
        return out
    from scipy.spatial import cKDTree

    # local seeds: a sample and two of its nearest neighbours, on one face almost surely
    tree, k = cKDTree(points), min(_LOCAL_SEED_NEIGHBOURS, len(points))
    misses = 0
    while len(out) < max_patches and np.count_nonzero(free) * sample_area >= min_area and misses < _MISSES:
        pool = np.flatnonzero(free)
        if len(pool) < 3:
            break
        tri = pool[rng.integers(0, len(pool), size=(seeds, 3))]
        local = seeds // 2
        hood = tree.query(points[tri[:local, 0]], k=k)[1].reshape(local, k)  # only the seeds' neighbours
        # neighbours still in the pool, drawn at random (a used one: keep the global draw)
        pick = hood[np.arange(local)[:, None], rng.integers(1, hood.shape[1], size=(local, 2))]
        tri[:local, 1:] = np.where(free[pick], pick, tri[:local, 1:])
        n = np.cross(points[tri[:, 1]] - points[tri[:, 0]], points[tri[:, 2]] - points[tri[:, 0]])
        length = np.linalg.norm(n, axis=1)
        ok = length > 0
        n = n[ok] / length[ok, None]
        tri = tri[ok]
        if not len(n):
            break
        n *= np.where(np.einsum("sk,sk->s", n, normals[tri].sum(axis=1)) < 0, -1.0, 1.0)[:, None]
        # (seeds, pool) inlier masks of the seed planes
        offset = points[pool] @ n.T - np.einsum("sk,sk->s", points[tri[:, 0]], n)
        inl = (np.abs(offset) < tol) & (normals[pool] @ n.T > cos_tol)
        members = pool[inl[:, int(np.argmax(inl.sum(axis=0)))]]
        patch, members = _refit(points, normals, pool, members, tol=tol, cos_tol=cos_tol, sample_area=sample_area)
        if len(members) == 0:
            break
        free[members] = False
        if patch is None or patch.area < min_area:
            # a small plane found first hides no large one: set it aside and look on
            misses += 1
            continue
        out.append(patch)
    return out


def _refit(points, normals, pool, members, *, tol, cos_tol, sample_area):
    """The least-squares plane of ``members``, its inliers among ``pool`` and their moments."""
    for _ in range(2):
        if len(members) < 3:
            return None, members
        c = points[members].mean(axis=0)
        _, _, vt = np.linalg.svd(points[members] - c, full_matrices=False)
        n = vt[2] if vt[2] @ normals[members].sum(axis=0) > 0 else -vt[2]
        near = (np.abs((points[pool] - c) @ n) < tol) & (normals[pool] @ n > cos_tol)
        members = pool[near]
    if len(members) < 3:
        return None, members
    c = points[members].mean(axis=0)
    flat = points[members] - c
    flat -= np.outer(flat @ n, n)
    w, v = np.linalg.eigh(flat.T @ flat / len(members))
    a1 = v[:, 2]
    a2 = np.cross(n, a1)
    axes = np.stack([a1, a2])
    return PlanarPatch(c, n, axes, np.sqrt(np.maximum(w[[2, 1]], 0.0)), float(len(members) * sample_area),
                       flat @ axes.T), members


def plane_placements(
    source: list[PlanarPatch], target: list[PlanarPatch], *, area_ratio: float = 1.5, cells: int = 48,
    step: float = 3.0, alternatives: int = 2,
) -> np.ndarray:
    """Placements ``T_target_source`` that lay each source plane on a target plane of a
    similar area (within ``area_ratio``), normals opposed, outlines on each other.

    Parameters
    ----------
    source, target : the planar patches of each fragment (:func:`planar_patches`)
    area_ratio : largest ratio of the two areas of a pair of planes
    cells : the wider patch spans about this many cells of the outline images
    step : degrees between the in-plane turns tried
    alternatives : in-plane alignments kept per pair of planes, best overlap first, each
        turned more than 20 degrees from those before (a symmetric outline has several)

    Returns
    -------
    (h, 4, 4) placements

    Notes
    -----
    The source patch, mirrored (it is seen from the other side), is turned in ``step``
    increments; for each turn the shift with the most overlap of the two occupancy images
    is their cross-correlation's peak (FFT). A clean cut is the same outline on both
    fragments, so the true turn and shift overlap it completely; contact counted with a
    tolerance hardly changes with the turn of a round face, the outline does.
    """
    out = []
    for p in source:
        for q in target:
            if max(p.area, q.area) > area_ratio * min(p.area, q.area):
                continue
            spacing = np.sqrt(max(p.area / len(p.flat), q.area / len(q.flat)))
            frame_p = np.stack([p.axes[0], p.axes[1], p.normal], axis=1)
            for angle, shift in in_plane_alignments(p.flat * [1.0, -1.0], q.flat, spacing=spacing, cells=cells,
                                                    step=step, alternatives=alternatives):
                c, s = np.cos(angle), np.sin(angle)
                # a1 -> the turned first axis, a2 -> the mirrored, turned second one, n -> -n'
                frame_q = np.stack([c * q.axes[0] + s * q.axes[1], s * q.axes[0] - c * q.axes[1], -q.normal], axis=1)
                R = frame_q @ frame_p.T
                moved = q.centre + shift[0] * q.axes[0] + shift[1] * q.axes[1]
                out.append(make_transform(R, moved - R @ p.centre))
    return np.array(out).reshape(-1, 4, 4)


def in_plane_alignments(a: np.ndarray, b: np.ndarray, *, spacing: float, cells: int = 48, step: float = 3.0,
                        alternatives: int = 2) -> list[tuple[float, np.ndarray]]:
    """[(angle, (2,) shift)]: the turns and shifts of points ``a`` (k, 2) whose occupancy
    image overlaps that of points ``b`` (m, 2) most, best first (``a @ [[c, s], [-s, c]] +
    shift`` lies on ``b``): a coarse search over every turn in ``step`` degrees, then each
    of ``alternatives`` turns (more than 20 degrees apart) refined within a step of it on
    images as fine as the samples allow (a cell of 1.5 sample ``spacing``, blurred: finer
    cells would be mostly empty)."""
    reach = max(np.abs(a).max(), np.abs(b).max())
    fine_cells = int(np.clip(2 * reach / (1.5 * spacing), cells, 8 * cells))
    coarse = _overlaps(a, b, np.radians(np.arange(0.0, 360.0, step)), reach=reach, cells=cells)
    kept: list = []
    for _, angle, _ in sorted(coarse, key=lambda x: -x[0]):
        if all(abs((angle - a0 + np.pi) % (2 * np.pi) - np.pi) > np.radians(20.0) for a0 in kept):
            kept.append(angle)
            if len(kept) == alternatives:
                break
    out = []
    for angle in kept:
        fine = angle + np.radians(np.linspace(-step, step, 13))
        _, best, shift = max(_overlaps(a, b, fine, reach=reach, cells=fine_cells, blur=True), key=lambda x: x[0])
        out.append((best, shift))
    return out


def _overlaps(a: np.ndarray, b: np.ndarray, angles: np.ndarray, *, reach: float, cells: int, blur: bool = False):
    """[(overlap, angle, (2,) shift)] per turn of ``a``: the peak of the cross-correlation
    of the two occupancy images (blurred by a cell, and the peak placed to a fraction of a
    cell by a parabola through it and its neighbours, when ``blur``).

    Notes
    -----
    Turns in batches: stacks of images (binned as :func:`numpy.histogram2d` bins them)
    and batched real FFTs, the target's transform computed once; the same arithmetic per
    turn as :func:`scipy.signal.fftconvolve` in ``full`` mode.
    """
    from scipy import fft as sp_fft
    from scipy.ndimage import gaussian_filter

    h = 2 * reach / cells
    size = cells + 3
    edges = (np.arange(size + 1) - size / 2) * h
    angles = np.asarray(angles, float)
    c, s = np.cos(angles), np.sin(angles)
    turns = np.stack([np.stack([c, s], axis=1), np.stack([-s, c], axis=1)], axis=1)  # (t, 2, 2): rows of each turn
    turned = np.matmul(a[None], turns)  # (t, k, 2): a @ turn, per turn

    def bins(x):  # the bin of each coordinate, as searchsorted(edges, x, "right") - 1 gives it
        i = np.clip(np.floor((x - edges[0]) / h).astype(np.int64), 0, size - 1)
        return i - (x < edges[i]) + (x >= edges[i + 1])

    def images(points):  # (t, k, 2) -> (t, size, size) occupancy, histogram2d's bins (right edges open)
        i, j = bins(points[..., 0]), bins(points[..., 1])
        inside = (i >= 0) & (i < size) & (j >= 0) & (j < size)
        img = np.zeros((len(points), size, size))
        img[np.nonzero(inside)[0], i[inside], j[inside]] = 1.0
        return gaussian_filter(img, (0.0, 1.0, 1.0)) if blur else img

    full = 2 * size - 1
    fshape = [sp_fft.next_fast_len(full, True)] * 2
    target = sp_fft.rfftn(images(b[None])[0], fshape)
    corr = np.empty((len(angles), full, full))
    chunk = max(1, 2**20 // (fshape[0] * fshape[1]))  # turns per batch: large images one at a time stay in cache
    for k in range(0, len(angles), chunk):
        source = sp_fft.rfftn(images(turned[k:k + chunk])[:, ::-1, ::-1], fshape, axes=(1, 2))
        corr[k:k + chunk] = sp_fft.irfftn(target * source, fshape, axes=(1, 2))[:, :full, :full]
    out = []
    for t, angle in enumerate(angles):
        k = np.array(np.unravel_index(int(np.argmax(corr[t])), corr[t].shape), float)
        peak = float(corr[t][tuple(k.astype(int))])
        if blur:
            for axis in range(2):
                i = k.astype(int)
                lo, hi = i.copy(), i.copy()
                lo[axis] -= 1
                hi[axis] += 1
                if lo[axis] >= 0 and hi[axis] < full:
                    y0, y1, y2 = corr[t][tuple(lo)], peak, corr[t][tuple(hi)]
                    curve = y0 - 2 * y1 + y2
                    if curve < 0:
                        k[axis] += 0.5 * (y0 - y2) / curve
        # the peak at index i of the full correlation: a shift of i - (size - 1) cells
        out.append((peak, float(angle), (k - (size - 1)) * h))
    return out


__all__ = ["PlanarPatch", "in_plane_alignments", "plane_placements", "planar_patches"]
