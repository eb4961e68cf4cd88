"""Planar break faces that the segmentation missed, found by their mates.

A break is two faces, one on each fragment, of the same outline. When one side of a planar
break is labelled fracture and the other is not, the unlabelled side is still there: a
plane of the other fragment's surface, labelled original, whose outline coincides with the
labelled face's once the two are laid together. Every break face has a mate, so a labelled
planar face whose best mate in the whole set is such an unlabelled plane marks that plane
as fracture. This is the complementarity cue of the segmentation (``docs/method/
segmentation.md``); it needs no threshold on roughness, only the outline overlap that a
clean break gives by construction.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .geometry import face_adjacency, face_areas, face_normals, sample_surface
from .parallel import pool_map, worker_state
from .planes import PlanarPatch, in_plane_alignments, planar_patches
from .segmentation import Segmentation, fracture_regions


@dataclasses.dataclass(frozen=True)
class _Plane:
    fragment: int
    labelled: bool  # labelled fracture (else: a plane of the surface labelled original)
    patch: PlanarPatch


def relabel_planar_mates(
    meshes: list[tuple[np.ndarray, np.ndarray]], segmentations: list[Segmentation], *,
    tol: float, min_area: float, min_overlap: float, samples: int = 20000, candidates: int = 16, max_planes: int = 64,
    rng: np.random.Generator, jobs: int = 1, scheduler: str | None = None,
) -> tuple[list[Segmentation], list[int]]:
    """The segmentations with the planar mates of labelled planar break faces labelled fracture.

    Parameters
    ----------
    meshes : (vertices (n, 3), faces (f, 3)) per fragment, as segmented
    segmentations : Segmentation per fragment (not modified)
    tol : largest distance of a point from its plane (mesh units: the contact tolerance)
    min_area : planes with less area are not considered (mesh units squared)
    min_overlap : the intersection over union of the two outlines, laid together, that
        makes a plane a mate
    samples : area-uniform surface samples per fragment
    candidates : outlines compared per labelled face: those of the planes of other
        fragments most alike in area and second moments
    max_planes : at most this many planes per fragment and label, largest first (a CAD
        part's unlabelled break face can be smaller than a dozen of its design faces)
    rng : numpy Generator
    jobs, scheduler : the outlines are compared in that many local processes, or on the
        Dask cluster at that address (:func:`parallel.pool_map`); the result does not
        depend on either

    Returns
    -------
    segmentations : a new Segmentation where faces were relabelled, else the one given
    relabelled : (k,) indices of the fragments that changed

    Notes
    -----
    A labelled face's mate is the plane of another fragment, labelled or not, of similar
    area whose outline overlaps it most (:func:`planes.in_plane_alignments`). Only when
    that best mate is unlabelled, and overlaps by ``min_overlap``, are its faces labelled
    fracture: a face whose labelled mate fits better is left as it is, and two planes of
    the original surface (a plate's two sides) are never compared. A mate has the same area
    and moments as the face, so only the ``candidates`` planes nearest in those (found in a
    k-d tree over the whole set) have their outlines compared: the work grows with the
    number of planes, not with its square, which matters with many similar faces
    (Voronoi cells: every cell face is alike in size). Only the unlabelled candidates'
    outlines decide whether a face has a mate to label, so the labelled candidates are
    compared only when one of those qualifies, and only until one fits better.
    """
    planes: list[_Plane] = []
    sample_areas = []
    for k, ((v, f), seg) in enumerate(zip(meshes, segmentations)):
        points, face = sample_surface(v, f, samples, rng=rng)
        normals = face_normals(v, f)[face]
        sample_area = float(face_areas(v, f).sum()) / samples
        sample_areas.append(sample_area)
        for labelled in (True, False):
            keep = seg.fracture[face] == labelled
            if np.count_nonzero(keep) < 3:
                continue
            for p in planar_patches(points[keep], normals[keep], sample_area, tol=tol, min_area=min_area,
                                    max_patches=max_planes, rng=rng):
                planes.append(_Plane(k, labelled, p))
    best: dict[int, tuple[float, int]] = {}  # unlabelled plane -> (overlap, labelled plane)
    tasks = _nearest_similar(planes, count=candidates)
    here = len(tasks) < _PARALLEL_FROM
    found = pool_map(_best_unlabelled_mate, tasks, jobs=1 if here else jobs, scheduler=None if here else scheduler,
                     initializer=_start, initargs=(planes, sample_areas, min_overlap))
    for (i, _), mate in zip(tasks, found):
        if mate is not None and mate[0] > best.get(mate[1], (0.0, -1))[0]:
            best[mate[1]] = (mate[0], i)
    out, changed = list(segmentations), []
    for j in sorted(best):
        k, patch = planes[j].fragment, planes[j].patch
        v, f = meshes[k]
        seg = out[k]
        on = _faces_on(v, f, patch, tol=tol, spacing=np.sqrt(sample_areas[k])) & ~seg.fracture
        if not on.any():
            continue
        fracture = seg.fracture | on
        area = face_areas(v, f)
        out[k] = dataclasses.replace(seg, fracture=fracture, region=fracture_regions(fracture, face_adjacency(f)[0]),
                                     fracture_area=float(area[fracture].sum()))
        if k not in changed:
            changed.append(k)
    return out, sorted(changed)


_PARALLEL_FROM = 64  # labelled planes: fewer are compared faster than worker processes start


def _start(planes: list[_Plane], sample_areas: list[float], min_overlap: float) -> None:
    worker_state.update(planes=planes, sample_areas=sample_areas, min_overlap=min_overlap)


def _best_unlabelled_mate(task: tuple[int, list[int]]) -> tuple[float, int] | None:
    """(overlap, plane) when the best mate of labelled plane ``i`` among ``similar`` is an
    unlabelled plane overlapping it by ``min_overlap``, else None.

    The same decision as the best of every candidate's overlap, with fewer outlines
    compared: the unlabelled candidates first, and the labelled ones only when an
    unlabelled one qualifies, until one of them fits better.
    """
    i, similar = task
    planes, sample_areas = worker_state["planes"], worker_state["sample_areas"]
    a = planes[i]

    def overlap(j):
        spacing = np.sqrt(max(sample_areas[a.fragment], sample_areas[planes[j].fragment]))
        return _outline_overlap(a.patch, planes[j].patch, spacing=spacing), j

    unlabelled = [overlap(j) for j in similar if not planes[j].labelled]
    if not unlabelled or max(unlabelled)[0] < worker_state["min_overlap"]:
        return None
    mate = max(unlabelled)
    if any(overlap(j) > mate for j in similar if planes[j].labelled):
        return None
    return mate


def _nearest_similar(planes: list[_Plane], *, count: int, ratio: float = 1.5):
    """[(labelled plane, [planes])]: per labelled plane, the planes of other fragments
    :func:`_similar` to it, at most ``count`` of them, nearest in log area and log spreads first."""
    from scipy.spatial import cKDTree

    if not planes:
        return []
    key = np.log(np.array([[p.patch.area, *p.patch.spread] for p in planes]).clip(1e-300))
    tree = cKDTree(key)
    out = []
    for i, a in enumerate(planes):
        if not a.labelled:
            continue
        near = tree.query_ball_point(key[i], r=np.log(ratio) + 1e-9, p=np.inf)
        near = [j for j in near if planes[j].fragment != a.fragment and _similar(a.patch, planes[j].patch, ratio)]
        near.sort(key=lambda j: (float(np.sum((key[j] - key[i]) ** 2)), j))
        out.append((i, near[:count]))
    return out


def _similar(p: PlanarPatch, q: PlanarPatch, ratio: float = 1.5) -> bool:
    """Mates have the same area and second moments: within ``ratio`` (a cheap test before
    the outlines)."""
    return (max(p.area, q.area) <= ratio * min(p.area, q.area)
            and bool(np.all(np.maximum(p.spread, q.spread) <= ratio * np.minimum(p.spread, q.spread))))


def _outline_overlap(p: PlanarPatch, q: PlanarPatch, *, spacing: float) -> float:
    """How far the two outlines coincide laid together (``p`` seen from the other side),
    at the in-plane turn and shift that overlap them most: the smaller of the shares of
    either's samples within two sample spacings of the other's (inside an outline every
    sample has such a neighbour almost surely; only outline that is not shared counts)."""
    from scipy.spatial import cKDTree

    a = p.flat * [1.0, -1.0]
    tree_b = cKDTree(q.flat)
    best = 0.0
    for angle, shift in in_plane_alignments(a, q.flat, spacing=spacing):
        c, s = np.cos(angle), np.sin(angle)
        moved = a @ np.array([[c, s], [-s, c]]) + shift
        tree_a = cKDTree(moved)
        covered_a = np.mean(tree_b.query(moved, distance_upper_bound=2.0 * spacing)[0] < np.inf)
        covered_b = np.mean(tree_a.query(q.flat, distance_upper_bound=2.0 * spacing)[0] < np.inf)
        best = max(best, float(min(covered_a, covered_b)))
    return best


def _faces_on(vertices: np.ndarray, faces: np.ndarray, patch: PlanarPatch, *, tol: float, spacing: float,
              normal_angle: float = 60.0) -> np.ndarray:
    """(f,) bool: faces whose centre lies on the patch's plane within ``tol``, facing its
    way within ``normal_angle``, inside its outline (cells of two sample spacings)."""
    centres = vertices[faces].mean(axis=1)
    rel = centres - patch.centre
    near = (np.abs(rel @ patch.normal) < tol) & (face_normals(vertices, faces) @ patch.normal > np.cos(np.radians(normal_angle)))
    cell = 2.0 * spacing
    occupied = np.floor(patch.flat / cell).astype(np.int64)
    lo = occupied.min(axis=0)
    image = np.zeros(occupied.max(axis=0) - lo + 1, bool)
    image[tuple((occupied - lo).T)] = True
    at = np.floor(rel[near] @ patch.axes.T / cell).astype(np.int64) - lo
    inside = np.all((at >= 0) & (at < image.shape), axis=1)
    inside[inside] = image[tuple(at[inside].T)]
    out = np.zeros(len(faces), bool)
    out[np.flatnonzero(near)[inside]] = True
    return out


__all__ = ["relabel_planar_mates"]
