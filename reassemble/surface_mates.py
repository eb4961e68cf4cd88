"""Smooth break faces found by their mates, whatever their labels.

A break leaves the same surface on two fragments, facing opposite ways. Where a break is
smoother than the object (a clean cut through a detailed figure), every roughness-based
cue labels it original and the object's detail fracture, on both sides of the break. Its
two sides are still each other's mates: laid together they coincide over their whole
outline, which the original surface of two fragments does not do (a convex outside never
fits another convex outside, and two faces of a design coincide only when they have the
same outline). This module finds such pairs among the crease-bounded smooth regions of
the set and labels them fracture. It needs no label and no threshold on roughness: only
the contact tolerance and the share of either region the other covers.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .geometry import (
    connected_components,
    face_adjacency,
    face_areas,
    face_normals,
    rotation_from_vector,
    sample_surface,
)
from .mates import _similar
from .registration import opposed_neighbours
from .segmentation import Segmentation, fracture_regions


@dataclasses.dataclass(frozen=True)
class Region:
    """A crease-bounded smooth region of one fragment.

    Attributes
    ----------
    fragment : index of the fragment
    faces : (k,) face indices
    area : its area
    points, normals : (m, 3) area-uniform samples and their face normals
    centre : (3,) area centroid
    axes : (3, 3) rows: the two in-plane principal axes (largest spread first) and the
        mean normal, a right-handed frame
    spread : (2,) square roots of the in-plane second moments
    """

    fragment: int
    faces: np.ndarray
    area: float
    points: np.ndarray
    normals: np.ndarray
    centre: np.ndarray
    axes: np.ndarray
    spread: np.ndarray


def smooth_regions(vertices: np.ndarray, faces: np.ndarray, *, crease: float, min_area: float) -> list[np.ndarray]:
    """Face sets of the connected regions whose neighbouring faces meet at less than ``crease``
    degrees, of at least ``min_area``, largest first.

    Parameters
    ----------
    vertices : (n, 3), faces : (f, 3)
    crease : dihedral angle (degrees) that separates regions
    min_area : smallest region kept (mesh units squared)
    """
    normals = face_normals(vertices, faces)
    pairs, _ = face_adjacency(faces)
    smooth = np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]]) > np.cos(np.radians(crease))
    n, label = connected_components(len(faces), pairs[smooth])
    area = np.bincount(label, face_areas(vertices, faces), n)
    keep = [k for k in np.argsort(-area, kind="stable") if area[k] >= min_area]
    return [np.flatnonzero(label == k) for k in keep]


def _region(fragment: int, vertices: np.ndarray, faces: np.ndarray, idx: np.ndarray, *, samples: int,
            rng: np.random.Generator) -> Region:
    sub = faces[idx]
    points, face = sample_surface(vertices, sub, samples, rng=rng)
    normals = face_normals(vertices, sub)[face]
    area = face_areas(vertices, sub)
    centre = points.mean(axis=0)
    X = points - centre
    w, v = np.linalg.eigh(X.T @ X / len(X))
    mean_normal = normals.mean(axis=0)
    n = mean_normal / max(np.linalg.norm(mean_normal), 1e-300)
    e1 = v[:, 2] - (v[:, 2] @ n) * n  # the largest spread, in the plane of the mean normal
    if np.linalg.norm(e1) < 1e-9:
        e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    axes = np.array([e1, np.cross(n, e1), n])
    flat = X @ axes[:2].T
    spread = np.sqrt(np.sort(np.linalg.eigvalsh(flat.T @ flat / len(flat)))[::-1].clip(0.0))
    return Region(fragment, idx, float(area.sum()), points, normals, centre, axes, spread)


def _point_to_plane(src: np.ndarray, dst: np.ndarray, dst_n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, t): the small rigid motion minimizing sum(((R src + t - dst) . n)^2), linearized."""
    A = np.hstack([np.cross(src, dst_n), dst_n])
    b = np.einsum("ij,ij->i", dst - src, dst_n)
    x = np.linalg.lstsq(A.T @ A + 1e-12 * np.eye(6), A.T @ b, rcond=None)[0]
    return rotation_from_vector(x[:3]), x[3:]


_FLIP = np.diag([1.0, -1.0, -1.0])  # the mate's frame seen from the other side (a rotation)


def _overlap(a: Region, b: Region, tree_a, tree_b, *, tol: float, spacing: float, turns: int = 12,
             iterations: int = 12) -> tuple[float, np.ndarray]:
    """(the smaller of the shares of either region's samples the other covers, R|t (3, 4)
    placing ``b`` on ``a``) at the best of ``turns`` in-plane turns of their frames laid
    face to face, each refined by point-to-plane ICP.

    A sample is covered when the other's nearest sample lies within ``2 spacing``, its
    plane within ``tol``, facing the opposite way."""
    best, best_T = 0.0, np.zeros((3, 4))
    for k in range(turns):
        theta = 2.0 * np.pi * k / turns
        c, s = np.cos(theta), np.sin(theta)
        Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        R = a.axes.T @ Rz @ _FLIP @ b.axes
        t = a.centre - R @ b.centre
        gate = max(8.0 * tol, 4.0 * spacing)
        for _ in range(iterations):
            moved = b.points @ R.T + t
            d, j = tree_a.query(moved, distance_upper_bound=gate)
            ok = np.isfinite(d)
            if np.count_nonzero(ok) < 6:
                break
            dR, dt = _point_to_plane(moved[ok], a.points[j[ok]], a.normals[j[ok]])
            R, t = dR @ R, dR @ t + dt
            gate = max(2.0 * tol, 2.0 * spacing, 0.7 * gate)
        cover = _covered(a, b, R, t, tree_a, tree_b, tol=tol, spacing=spacing)
        if cover > best:
            best, best_T = cover, np.hstack([R, t[:, None]])
    return best, best_T


def _covered(a: Region, b: Region, R: np.ndarray, t: np.ndarray, tree_a, tree_b, *, tol: float,
             spacing: float) -> float:
    """The smaller of the shares of a's samples covered by b placed by (R, t), and of b's by a:
    a sample is covered where the other's nearest sample lies within ``2 spacing``, faces it
    (:func:`registration.opposed_neighbours`) and has it on its plane within ``tol``."""

    def share(points, normals, onto: Region, tree) -> float:
        ok, j = opposed_neighbours(tree, points, normals, onto.normals, reach=2.0 * spacing, cos_tol=0.5)
        ok[ok] = np.abs(np.einsum("ij,ij->i", points[ok] - onto.points[j[ok]], onto.normals[j[ok]])) < tol
        return float(np.mean(ok))

    share_b = share(b.points @ R.T + t, b.normals @ R.T, a, tree_a)
    return min(share_b, share((a.points - t) @ R, a.normals @ R, b, tree_b))  # a in b's frame


def relabel_surface_mates(
    meshes: list[tuple[np.ndarray, np.ndarray]], segmentations: list[Segmentation], *,
    tol: float, min_area: float, min_overlap: float, crease: float = 30.0, samples: int = 300,
    max_regions: int = 16, ratio: float = 1.5, rng: np.random.Generator,
) -> tuple[list[Segmentation], list[int]]:
    """The segmentations with every smooth region that has a mate on another fragment labelled fracture.

    Parameters
    ----------
    meshes : (vertices (n, 3), faces (f, 3)) per fragment, as segmented
    segmentations : Segmentation per fragment (not modified)
    tol : contact tolerance (mesh units)
    min_area : regions with less area are not considered (mesh units squared)
    min_overlap : the share of either region the other must cover, laid together
    crease : dihedral angle (degrees) bounding the regions
    samples : samples per region
    max_regions : the largest this many regions per fragment
    ratio : mates' areas and spreads agree within it
    rng : numpy Generator

    Returns
    -------
    segmentations : a new Segmentation where faces were relabelled, else the one given
    relabelled : (k,) indices of the fragments that changed

    Notes
    -----
    Each pair of regions of different fragments alike in area and spreads is laid face to
    face (centroids together, mean normals opposite, in-plane axes at 12 turns) and refined
    by point-to-plane ICP; it is a mate when each covers ``min_overlap`` of the other (both
    ways: a small flat region laid inside a large one covers only itself). Each region
    keeps its best mate. A region labelled original whose best mate qualifies becomes
    fracture; labels elsewhere are kept.
    """
    from scipy.spatial import cKDTree

    regions: list[Region] = []
    for k, (v, f) in enumerate(meshes):
        for idx in smooth_regions(v, f, crease=crease, min_area=min_area)[:max_regions]:
            regions.append(_region(k, v, f, idx, samples=samples, rng=rng))
    trees = [cKDTree(r.points) for r in regions]
    best = [(0.0, -1)] * len(regions)
    for i, a in enumerate(regions):
        for j in range(i + 1, len(regions)):
            b = regions[j]
            if b.fragment == a.fragment or not _similar(a, b, ratio):
                continue
            spacing = np.sqrt(max(a.area, b.area) / samples)
            cover, _ = _overlap(a, b, trees[i], trees[j], tol=tol, spacing=spacing)
            if cover > best[i][0]:
                best[i] = (cover, j)
            if cover > best[j][0]:
                best[j] = (cover, i)
    out, changed = list(segmentations), []
    for i, (cover, _) in enumerate(best):
        if cover < min_overlap:
            continue
        r = regions[i]
        seg = out[r.fragment]
        if seg.fracture[r.faces].all():
            continue
        v, f = meshes[r.fragment]
        fracture = seg.fracture.copy()
        fracture[r.faces] = True
        out[r.fragment] = dataclasses.replace(
            seg, fracture=fracture, region=fracture_regions(fracture, face_adjacency(f)[0]),
            fracture_area=float(face_areas(v, f)[fracture].sum()))
        if r.fragment not in changed:
            changed.append(r.fragment)
    return out, sorted(changed)


__all__ = ["Region", "relabel_surface_mates", "smooth_regions"]
