"""Thin-walled fragments (sherds of a vessel): wall thickness, break strips, strip frames.

A sherd is two smooth walls (outside and inside of the vessel) joined along its outline by
a break strip about one wall thickness wide. Its break is a band, not a surface: the
integral-invariant signatures at radii larger than the wall see the walls, not the break,
and the ball normals of mates there are far from opposed (the strip frames below are much
closer; ``python -m benchmarks.accuracy.vessel --diagnose``). Sherds are matched along
their strips instead (``docs/method/thin_walls.md``):

- the strip is what is not wall: a ray cast inward from a wall face meets the opposite wall
  (an antiparallel face) within about one thickness; from a strip face it runs along the
  wall (:func:`wall_thickness`, :func:`strip_segmentation`);
- every strip keypoint gets a frame: the strip normal n (out of the material, across the
  strip) and the tangent t along the break (:func:`strip_frames`). Mates have n opposed and
  t parallel or antiparallel, so one correspondence fixes a rigid motion
  (:func:`registration.frame_hypotheses`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .geometry import face_areas, face_normals, make_scene, sample_surface

SHELL_THICKNESS = 0.08  # a set is thin-walled when its median wall is under this fraction of a fragment's diagonal
WALL_AXIS_COS = np.cos(np.radians(20.0))  # wall normals within this of a wall's main axis define it
MAX_WALL_SAMPLES = 200_000  # points spread over a sherd's walls for their local axis (strip_frames)
SHELL_WALL_SHARE = 0.6  # ... and walls (faces with an opposite face within 2 thicknesses) are most of the surface


def wall_thickness(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(f,) distance from each face centre, inward along its normal, to an opposite wall.

    ``inf`` where the inward ray meets nothing or a face that is not antiparallel (within
    about 37 degrees): a strip face, whose ray runs along the wall.
    """
    centres = vertices[faces].mean(axis=1)
    normals = face_normals(vertices, faces)
    eps = 1e-4 * float(np.linalg.norm(np.ptp(vertices, axis=0)))
    rays = np.hstack([centres - eps * normals, -normals]).astype(np.float32)
    hit = make_scene(vertices, faces).cast_rays(rays)
    t = hit["t_hit"].numpy().astype(float)
    pid = hit["primitive_ids"].numpy().astype(np.int64)
    out = np.full(len(faces), np.inf)
    ok = np.isfinite(t)
    ok[ok] = np.einsum("ij,ij->i", normals[ok], normals[pid[ok]]) < -0.8
    out[ok] = t[ok] + eps
    return out


def walls(thickness: np.ndarray) -> tuple[np.ndarray, float]:
    """(f,) wall mask (an opposite wall within 2 median thicknesses) and the median wall
    thickness (inf when there are no walls), from :func:`wall_thickness`."""
    finite = thickness[np.isfinite(thickness)]
    if len(finite) == 0:
        return np.zeros(len(thickness), bool), np.inf
    median = float(np.median(finite))
    return thickness < 2.0 * median, median


def is_thin_shell(vertices: np.ndarray, faces: np.ndarray, thickness: np.ndarray) -> bool:
    """Whether a fragment is a thin-walled sherd: walls are most of its surface and thin
    against its size. A solid's "wall" is its far side, well above the threshold
    (``python -m benchmarks.accuracy.thin_walls`` measures both over a puzzle set)."""
    wall, median = walls(thickness)
    area = face_areas(vertices, faces)
    diag = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    return bool(median < SHELL_THICKNESS * diag and area[wall].sum() > SHELL_WALL_SHARE * area.sum())


def strip_segmentation(vertices: np.ndarray, faces: np.ndarray, thickness: np.ndarray):
    """Segmentation of a sherd: fracture = the strip (every face that is not wall).

    The vessel's own rim and base are strips too: nothing here tells them from a break;
    the registration's contact and penetration scores and the assembly's consistency have to.
    """
    from .geometry import face_adjacency
    from .segmentation import Segmentation, fracture_regions

    wall, _ = walls(thickness)
    strip = ~wall
    area = face_areas(vertices, faces)
    return Segmentation(fracture=strip, probability=strip.astype(float), patch=np.arange(len(faces)),
                        region=fracture_regions(strip, face_adjacency(faces)[0]),
                        fracture_area=float(area[strip].sum()), area=float(area.sum()))


def strip_frames(
    vertices: np.ndarray, faces: np.ndarray, thickness: np.ndarray, keypoints: np.ndarray, normals: np.ndarray, *,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Strip normal and break tangent at each strip keypoint.

    Parameters
    ----------
    vertices, faces : the sherd
    thickness : (f,) :func:`wall_thickness`
    keypoints : (k, 3) points on the strip
    normals : (k, 3) rough outward normals there (they fix the sign of the strip normal)
    rng : numpy Generator (the points spread over the walls)

    Returns
    -------
    n : (k, 3) unit strip normals: perpendicular to the break tangent and to the wall's axis
        (the main axis of the normals at points spread over the walls by area within 1.5
        thicknesses, either side, refitted on those within 20 degrees of it)
    t : (k, 3) unit tangents: the main direction of the strip keypoints within 2.5
        thicknesses, across the wall normal (sign arbitrary)
    """
    wall, median = walls(thickness)
    fn, area = face_normals(vertices, faces), face_areas(vertices, faces)
    W = np.flatnonzero(wall)
    if len(W) == 0:  # no wall to lean on: the rough normals, and any tangent across them
        n = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
        t = np.cross(n, np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]))
        return n, t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)
    # the wall near a keypoint from points spread over the wall by area, not from face
    # centres: a CAD part's or a tile's wall is a few large triangles whose centres lie far
    # from the break, where the only "wall" centres near it are small faces of the break itself
    count = int(np.clip(area[W].sum() / (0.5 * median) ** 2, len(W), MAX_WALL_SAMPLES))
    spots, which = sample_surface(vertices, faces[W], count, rng=rng)
    which = W[which]
    tree = cKDTree(spots)
    _, nearest = tree.query(keypoints)
    w = np.empty_like(keypoints)
    for i, hood in enumerate(tree.query_ball_point(keypoints, 1.5 * median)):
        hood = which[np.asarray(hood, dtype=np.int64)]
        if len(hood) == 0:
            w[i] = fn[which[nearest[i]]]
            continue
        # the wall's axis, whichever side: the main axis of the normals (aligned to one
        # side, they cancel where a rib or flange stands on the wall)
        axis = np.linalg.eigh(fn[hood].T @ fn[hood])[1][:, -1]
        # again on the normals near that axis: a rough break's own faces, some of them
        # "wall" by the ray test, tilt it otherwise
        near = fn[hood][np.abs(fn[hood] @ axis) > WALL_AXIS_COS]
        w[i] = np.linalg.eigh(near.T @ near)[1][:, -1] if len(near) else axis
    w /= np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-300)
    t = np.empty_like(keypoints)
    for i, hood in enumerate(cKDTree(keypoints).query_ball_point(keypoints, 2.5 * median)):
        q = keypoints[hood] - keypoints[hood].mean(axis=0)
        q -= np.outer(q @ w[i], w[i])
        t[i] = np.linalg.svd(q, full_matrices=False)[2][0] if len(hood) > 2 else np.cross(w[i], normals[i])
    t -= np.einsum("ij,ij->i", t, w)[:, None] * w
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)
    n = np.cross(t, w)
    n *= np.where(np.einsum("ij,ij->i", n, normals) < 0, -1.0, 1.0)[:, None]
    return n, t


__all__ = ["is_thin_shell", "strip_frames", "strip_segmentation", "wall_thickness", "walls"]
