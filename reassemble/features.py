"""Multi-scale signatures on fracture surfaces, and what a mating surface's signature looks like.

A signature is scale-free: each radius contributes ``H_rob · r`` (mean curvature from V_r
and P_r) and ``|κ1 − κ2| · r`` (from the covariance of ball ∩ solid, or from D2_r). Two
mating fracture surfaces are complementary: the solid of one is the empty space of the
other, so H changes sign while |κ1 − κ2| is unchanged; :func:`mate_signature` gives the
signature a mating point should have.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .geometry import face_adjacency, face_areas, face_normals, sample_surface
from .segmentation import Segmentation


@dataclass(frozen=True)
class FeatureParams:
    """Options of the features stage; lengths are fractions of the reference size.

    Parameters
    ----------
    keypoint_spacing : spacing of fracture keypoints
    shell_spacing : keypoint spacing of thin-walled sherds, as a multiple of ``keypoint_spacing``
    samples : fracture and surface samples per fragment (ICP, contact, penetration)
    signature_radii : the signatures use this many of the finest descriptor radii (None:
        all of them); two by default: the coarsest ball reaches past a small contact into
        the air and other fragments, and with it the signatures of small mating faces
        disagree (``benchmarks/pairwise.py --signature-radii``)
    """

    keypoint_spacing: float = 0.015
    shell_spacing: float = 2.0
    samples: int = 4000
    signature_radii: int | None = 2


@dataclass
class FractureSurface:
    """What registration needs of one fragment.

    Attributes
    ----------
    keypoints : (k, 3) points on the fracture surface, about ``spacing`` apart
    keypoint_normals : (k, 3) outward unit normals there (of ball ∩ solid at the finest radius)
    signature : (k, s) scale-free multi-scale signature
    samples : (q, 3) area-uniform samples of the fracture surface
    sample_normals : (q, 3) face normals at the samples
    sample_area : float, fracture area each sample stands for
    surface : (p, 3) area-uniform samples of the whole surface (for penetration)
    surface_area : float, whole-surface area each of those stands for
    fracture_area, area : float
    keypoint_tangents : (k, 3) break tangents at the keypoints of a thin-walled fragment
        (:func:`shells.strip_frames`; sign arbitrary), None for solids
    surface_normals : (p, 3) face normals at the whole-surface samples, None where unknown
    surface_original : (p,) bool, whole-surface samples on faces not labelled fracture (of a
        fragment matched by its whole surface: that the evidence found original), None
        where unknown (both for :func:`registration.seam_continuity`)
    rim : (r, 3) points on the rim, the mesh edges between fracture and original faces (their
        midpoints), None where unknown (:func:`rim_points`)
    rim_directions : (r, 3) unit directions across the rim, in the fracture surface, from the
        fracture towards the original surface
    """

    keypoints: np.ndarray
    keypoint_normals: np.ndarray
    signature: np.ndarray
    samples: np.ndarray
    sample_normals: np.ndarray
    sample_area: float
    surface: np.ndarray
    surface_area: float
    fracture_area: float
    area: float
    keypoint_tangents: np.ndarray | None = None
    surface_normals: np.ndarray | None = None
    surface_original: np.ndarray | None = None
    rim: np.ndarray | None = None
    rim_directions: np.ndarray | None = None


def rim_points(
    vertices: np.ndarray, faces: np.ndarray, fracture: np.ndarray, *, radius: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where a fracture surface ends: its rim, and the direction across it.

    Parameters
    ----------
    vertices, faces : the fragment
    fracture : (f,) bool, faces labelled fracture
    radius : the directions are averaged over the rim within this distance (mesh units): a
        rim between labelled triangles zigzags, its mean course does not

    Returns
    -------
    points : (r, 3) midpoints of the edges between a fracture and an original face
    directions : (r, 3) unit vectors in the fracture surface, across the rim's mean course,
        pointing out of the fracture region
    lengths : (r,) edge lengths

    Notes
    -----
    Two mates share their break, so they share its outline: at the true placement each rim
    point of one lies on the other's rim, with the same direction across it. Contact alone
    leaves a smooth break free to slide along itself (by a few tolerances under scan noise);
    the outline pins it. Points whose neighbourhood gives no clear direction (a rim shorter
    than ``radius``, or folded on itself) are left out.
    """
    from scipy.sparse import coo_matrix
    from scipy.spatial import cKDTree

    fracture = np.asarray(fracture, bool)
    pairs, edges = face_adjacency(faces)
    cross = fracture[pairs[:, 0]] != fracture[pairs[:, 1]]
    empty = np.zeros((0, 3))
    if not cross.any():
        return empty, empty, np.zeros(0)
    pairs, edges = pairs[cross], edges[cross]
    inner = np.where(fracture[pairs[:, 0]], pairs[:, 0], pairs[:, 1])
    a, b = vertices[edges[:, 0]], vertices[edges[:, 1]]
    points, lengths = 0.5 * (a + b), np.linalg.norm(b - a, axis=1)
    normal = face_normals(vertices, faces)[inner]
    # each edge's own direction across: in the fracture face, out of it
    across = np.cross(normal, b - a)
    inside = points - vertices[faces[inner]].mean(axis=1)
    across *= np.where(np.einsum("ij,ij->i", across, inside) < 0, -1.0, 1.0)[:, None]
    across /= np.maximum(np.linalg.norm(across, axis=1, keepdims=True), 1e-300)
    # sums over each point's neighbours within the radius (itself included), as one sparse product
    close = cKDTree(points).query_pairs(radius, output_type="ndarray")
    rows = np.concatenate([close[:, 0], close[:, 1], np.arange(len(points))])
    cols = np.concatenate([close[:, 1], close[:, 0], np.arange(len(points))])
    near = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(points),) * 2).tocsr()
    n = near @ (lengths[:, None] * normal)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    # summed by length, a zigzag's directions add up to its mean course turned by 90 degrees
    u = near @ (lengths[:, None] * across)
    u -= np.einsum("ij,ij->i", u, n)[:, None] * n
    norm = np.linalg.norm(u, axis=1)
    keep = norm > 0.3 * (near @ lengths)  # a clear course keeps a good part of the summed length
    directions = u / np.maximum(norm, 1e-300)[:, None]
    return points[keep], directions[keep], lengths[keep]


def offset_surface(surface: FractureSurface, distance: float) -> FractureSurface:
    """``surface`` with its fracture samples and keypoints moved ``distance`` out along their
    normals: where a mate's surface lies when the two are ``distance`` apart. Signatures,
    normals and the whole-surface samples (for penetration) are unchanged."""
    if distance == 0.0:
        return surface
    return dataclasses.replace(surface, samples=surface.samples + distance * surface.sample_normals,
                               keypoints=surface.keypoints + distance * surface.keypoint_normals)


def signature(descriptors, *, radii: int | None = None) -> np.ndarray:
    """(n, 2m) signature from Descriptors with ``principal``: H_rob r, then |κ1 − κ2| r, at
    the finest ``radii`` radii (m of them; None: all)."""
    m = len(descriptors.radii) if radii is None else radii
    r = descriptors.radii[None, :m]
    return np.hstack([descriptors.H_rob[:, :m] * r, np.sqrt(np.maximum(descriptors.K2_cov[:, :m], 0.0)) * r])


def mate_signature(sig: np.ndarray) -> np.ndarray:
    """The signature a point mating with ``sig`` should have: H flips sign, |κ1 − κ2| does not."""
    out = np.array(sig, dtype=float, copy=True)
    out[:, : sig.shape[1] // 2] *= -1.0
    return out


def _grid_subsample(points: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """One point per cubic cell of edge ``spacing`` (the one nearest the cell centre).

    Returns
    -------
    chosen : (k,) indices of the chosen points, one per cell, in cell order
    cell : (n,) the cell (0..k-1) of every point
    """
    grid = np.floor(points / spacing)
    offset = np.linalg.norm(points / spacing - grid - 0.5, axis=1)
    cell = np.unique(grid, axis=0, return_inverse=True)[1].ravel()
    order = np.lexsort((offset, cell))
    first = np.r_[True, cell[order][1:] != cell[order][:-1]]
    return order[first], cell


def empty_surface(
    vertices: np.ndarray, faces: np.ndarray, *, n_radii: int, n_samples: int, rng: np.random.Generator
) -> FractureSurface:
    """The FractureSurface of a fragment with no fracture found: nothing to match, surface kept for collisions."""
    total = float(face_areas(vertices, faces).sum())
    surface, which = sample_surface(vertices, faces, n_samples, rng=rng)
    empty = np.zeros((0, 3))
    return FractureSurface(empty, empty, np.zeros((0, 2 * n_radii)), empty, empty, 0.0, surface,
                           total / n_samples, 0.0, total, surface_normals=face_normals(vertices, faces)[which],
                           surface_original=np.ones(len(surface), bool))


def fracture_surface(
    vertices: np.ndarray,
    faces: np.ndarray,
    segmentation: Segmentation,
    descriptors,
    *,
    spacing: float,
    n_samples: int = 4000,
    signature_radii: int | None = None,
    rng: np.random.Generator,
) -> FractureSurface:
    """Keypoints, signatures and samples of one fragment's fracture surface.

    Parameters
    ----------
    vertices, faces : the fragment
    segmentation : its Segmentation
    descriptors : Descriptors at the face centres, with ``principal``
    spacing : keypoint spacing (mesh units)
    n_samples : samples of the fracture surface, and of the whole surface
    signature_radii : the signatures use this many of the finest radii (None: all)
    rng : numpy Generator for the sampling
    """
    fracture = np.flatnonzero(segmentation.fracture)
    if len(fracture) == 0:
        n_radii = len(descriptors.radii) if signature_radii is None else signature_radii
        return empty_surface(vertices, faces, n_radii=n_radii, n_samples=n_samples, rng=rng)
    area = face_areas(vertices, faces)
    total = float(area.sum())
    surface, on_face = sample_surface(vertices, faces, n_samples, rng=rng)
    centres = vertices[faces[fracture]].mean(axis=1)
    chosen, cell = _grid_subsample(centres, spacing)
    keep = fracture[chosen]
    normals = descriptors.normal[keep, 0]  # of ball ∩ solid: smooth; measured better than cell-mean face normals
    sub = faces[fracture]
    samples, which = sample_surface(vertices, sub, n_samples, rng=rng)
    frac_area = float(area[fracture].sum())
    rim, rim_directions, _ = rim_points(vertices, faces, segmentation.fracture, radius=spacing)
    return FractureSurface(
        keypoints=vertices[faces[keep]].mean(axis=1),
        keypoint_normals=normals,
        signature=signature(descriptors, radii=signature_radii)[keep],
        samples=samples,
        sample_normals=face_normals(vertices, sub)[which],
        sample_area=frac_area / n_samples,
        surface=surface,
        surface_area=total / n_samples,
        fracture_area=frac_area,
        area=total,
        surface_normals=face_normals(vertices, faces)[on_face],
        surface_original=(~np.asarray(segmentation.fracture, bool) if segmentation.original is None
                          else np.asarray(segmentation.original, bool))[on_face],
        rim=rim,
        rim_directions=rim_directions,
    )


def same_surface(a, b) -> bool:
    """Whether two surfaces (dataclasses of arrays, as :class:`FractureSurface`) hold the
    same values, array by array: what a registration made on one would make on the other."""
    if a is b:
        return True
    if type(a) is not type(b):
        return False
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            if not (isinstance(x, np.ndarray) and isinstance(y, np.ndarray) and x.dtype == y.dtype
                    and np.array_equal(x, y)):
                return False
        elif x != y:
            return False
    return True
