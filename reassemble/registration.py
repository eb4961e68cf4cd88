"""Pairwise registration of two fragments along their fracture surfaces.

1. correspondences: each source keypoint's mate signature (H flipped) against the target's
   signatures (k-d tree), both ways;
2. RANSAC over 3-point hypotheses, pruned before any fit by rigidity (the three pairwise
   distances agree) and by the angles between the normals; fitted by Kabsch, then kept
   only if the normals face each other; scored by keypoint inliers (near and opposed);
3. the best distinct hypotheses refined by point-to-plane ICP (Open3D) between the two
   fracture surfaces;
4. every candidate scored by contact (source fracture area within a tolerance of the
   target, normals opposed) minus interpenetration (surface area of either fragment that
   lies inside the other, from Open3D signed distances), over the smaller fragment's area.

Transforms are ``T_target_source``: they map source coordinates into the target's frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .features import FractureSurface, mate_signature
from .geometry import invert_transform, rotation_angle_deg, transform_points


@dataclass(frozen=True)
class RegistrationParams:
    """Options of :func:`register_pair`; lengths are fractions of the reference size.

    Parameters
    ----------
    tolerance : contact tolerance after ICP
    ransac_tolerance : inlier distance and rigidity tolerance of the RANSAC hypotheses
    neighbours : signature neighbours per keypoint
    hypotheses : 3-point samples drawn
    max_scored : hypotheses passing the checks that are scored
    candidates : distinct hypotheses refined by ICP and returned
    normal_angle : degrees: agreement of normal angles within a triple, and the largest
        deviation from exactly opposed normals of an inlier
    penetration_weight : penalty per unit of interpenetrating area against contact area
    min_score : below it the verdict is "these two do not touch"
    """

    tolerance: float = 0.006
    ransac_tolerance: float = 0.02
    neighbours: int = 3
    hypotheses: int = 40000
    max_scored: int = 4000
    candidates: int = 6
    normal_angle: float = 30.0
    penetration_weight: float = 2.0
    min_score: float = 0.02


@dataclass
class Candidate:
    """One registration of a pair.

    Attributes
    ----------
    T_target_source : (4, 4) maps source coordinates into the target frame
    score : (contact − weight · penetration) / the smaller fragment's area
    contact_area : source fracture area in contact with the target
    penetration_area : surface area of either fragment inside the other
    inliers : keypoint inliers of the RANSAC hypothesis
    """

    T_target_source: np.ndarray
    score: float
    contact_area: float
    penetration_area: float
    inliers: int


@dataclass
class PairResult:
    """Ranked candidates of a pair; ``touching`` is the verdict of the best one."""

    candidates: list[Candidate]
    touching: bool
    matches: np.ndarray  # (c, 2) source/target keypoint indices of the best candidate's inliers

    @property
    def best(self) -> Candidate | None:
        return self.candidates[0] if self.candidates else None


def correspondences(source: FractureSurface, target: FractureSurface, *, neighbours: int) -> np.ndarray:
    """(c, 2) unique (source, target) keypoint pairs whose signatures are complementary."""
    from scipy.spatial import cKDTree

    k = min(neighbours, len(target.keypoints), len(source.keypoints))
    _, j = cKDTree(target.signature).query(mate_signature(source.signature), k=k)
    forward = np.column_stack([np.repeat(np.arange(len(source.keypoints)), k), np.asarray(j).reshape(-1)])
    _, i = cKDTree(source.signature).query(mate_signature(target.signature), k=k)
    backward = np.column_stack([np.asarray(i).reshape(-1), np.repeat(np.arange(len(target.keypoints)), k)])
    return np.unique(np.vstack([forward, backward]), axis=0)


def kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(h, 4, 4) rigid transforms minimizing ``|T a − b|`` for (h, n, 3) point sets."""
    ca, cb = a.mean(axis=1), b.mean(axis=1)
    H = np.einsum("hni,hnj->hij", a - ca[:, None], b - cb[:, None])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("hij,hjk->hik", U, Vt)))
    D = np.tile(np.eye(3), (len(a), 1, 1))
    D[:, 2, 2] = d
    R = np.einsum("hji,hjk,hlk->hil", Vt, D, U)  # V D U^T
    T = np.tile(np.eye(4), (len(a), 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = cb - np.einsum("hij,hj->hi", R, ca)
    return T


def ransac(
    source: FractureSurface,
    target: FractureSurface,
    pairs: np.ndarray,
    *,
    tol: float,
    params: RegistrationParams,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Hypotheses from 3-point samples of ``pairs``: (h, 4, 4) transforms and (h,) inlier counts, best first."""
    from scipy.spatial import cKDTree

    if len(pairs) < 3:
        return np.zeros((0, 4, 4)), np.zeros(0, int)
    pick = rng.integers(len(pairs), size=(params.hypotheses, 3))
    a = source.keypoints[pairs[pick, 0]]
    b = target.keypoints[pairs[pick, 1]]
    na = source.keypoint_normals[pairs[pick, 0]]
    nb = target.keypoint_normals[pairs[pick, 1]]
    cos_tol = np.cos(np.radians(params.normal_angle))
    ok = np.ones(len(pick), bool)
    for i, j in ((0, 1), (1, 2), (0, 2)):
        da = np.linalg.norm(a[:, i] - a[:, j], axis=1)
        db = np.linalg.norm(b[:, i] - b[:, j], axis=1)
        ok &= (np.abs(da - db) < tol) & (da > 3 * tol)
        ang_a = np.einsum("hi,hi->h", na[:, i], na[:, j])
        ang_b = np.einsum("hi,hi->h", nb[:, i], nb[:, j])
        ok &= np.abs(np.arccos(np.clip(ang_a, -1, 1)) - np.arccos(np.clip(ang_b, -1, 1))) < np.radians(params.normal_angle)
    idx = np.flatnonzero(ok)[: params.max_scored]
    if len(idx) == 0:
        return np.zeros((0, 4, 4)), np.zeros(0, int)
    T = kabsch(a[idx], b[idx])
    rotated = np.einsum("hij,hkj->hki", T[:, :3, :3], na[idx])
    facing = np.all(np.einsum("hki,hki->hk", rotated, nb[idx]) < -cos_tol, axis=1)
    T = T[facing]
    if len(T) == 0:
        return T, np.zeros(0, int)
    # inliers among (a subsample of) the source keypoints
    probe = rng.permutation(len(source.keypoints))[:300]
    p, n = source.keypoints[probe], source.keypoint_normals[probe]
    moved = np.einsum("hij,kj->hki", T[:, :3, :3], p) + T[:, None, :3, 3]
    turned = np.einsum("hij,kj->hki", T[:, :3, :3], n)
    dist, near = cKDTree(target.keypoints).query(moved.reshape(-1, 3), distance_upper_bound=tol)
    hit = np.isfinite(dist)
    opposed = np.zeros_like(hit)
    opposed[hit] = np.einsum("ij,ij->i", turned.reshape(-1, 3)[hit], target.keypoint_normals[near[hit]]) < -cos_tol
    inliers = opposed.reshape(len(T), -1).sum(axis=1)
    order = np.argsort(-inliers, kind="stable")
    return T[order], inliers[order]


def _distinct(T: np.ndarray, count: int, *, tol: float) -> list[int]:
    """Indices of up to ``count`` transforms, each differing from the ones before by > 5° or > tol."""
    chosen: list[int] = []
    for i in range(len(T)):
        if all(rotation_angle_deg(T[i, :3, :3], T[j, :3, :3]) > 5.0
               or np.linalg.norm(T[i, :3, 3] - T[j, :3, 3]) > tol for j in chosen):
            chosen.append(i)
            if len(chosen) == count:
                break
    return chosen


def icp(source: FractureSurface, target: FractureSurface, T: np.ndarray, *, tol: float) -> np.ndarray:
    """Point-to-plane ICP of the source fracture samples onto the target's, from ``T``, coarse to fine."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source.samples))
    dst = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target.samples))
    dst.normals = o3d.utility.Vector3dVector(target.sample_normals)
    for distance in (4 * tol, 2 * tol, tol):
        T = reg.registration_icp(
            src, dst, distance, T, reg.TransformationEstimationPointToPlane(),
            reg.ICPConvergenceCriteria(max_iteration=30),
        ).transformation
    return np.asarray(T)


def contact_score(
    source: FractureSurface,
    target: FractureSurface,
    T_target_source: np.ndarray,
    *,
    source_scene,
    target_scene,
    tol: float,
    params: RegistrationParams,
) -> tuple[float, float, float]:
    """(score, contact area, penetration area) of a placement."""
    import open3d as o3d

    cos_tol = np.cos(np.radians(params.normal_angle))
    moved = transform_points(T_target_source, source.samples).astype(np.float32)
    turned = source.sample_normals @ T_target_source[:3, :3].T
    closest = target_scene.compute_closest_points(o3d.core.Tensor(moved))
    dist = np.linalg.norm(closest["points"].numpy() - moved, axis=1)
    opposed = np.einsum("ij,ij->i", turned, closest["primitive_normals"].numpy()) < -cos_tol
    contact = float(np.count_nonzero((dist < tol) & opposed)) * source.sample_area
    # penetration both ways: whole-surface samples deeper than the tolerance inside the other
    inside_t = target_scene.compute_signed_distance(
        o3d.core.Tensor(transform_points(T_target_source, source.surface).astype(np.float32))).numpy() < -tol
    inside_s = source_scene.compute_signed_distance(
        o3d.core.Tensor(transform_points(invert_transform(T_target_source), target.surface).astype(np.float32))
    ).numpy() < -tol
    penetration = (float(inside_t.sum()) * source.surface_area + float(inside_s.sum()) * target.surface_area)
    smaller = min(source.area, target.area)
    return (contact - params.penetration_weight * penetration) / smaller, contact, penetration


def register_pair(
    source: FractureSurface,
    target: FractureSurface,
    *,
    source_scene,
    target_scene,
    size: float,
    params: RegistrationParams = RegistrationParams(),
    rng: np.random.Generator,
) -> PairResult:
    """Ranked candidate placements of ``source`` against ``target``.

    Parameters
    ----------
    source, target : FractureSurface of each fragment
    source_scene, target_scene : Open3D RaycastingScenes of the two closed meshes
    size : reference size (mesh units) for the tolerances
    params : RegistrationParams
    rng : numpy Generator

    Returns
    -------
    PairResult, candidates best first; ``touching`` False when no candidate scores
    ``min_score`` or neither fragment has a fracture surface
    """
    tol, rtol = params.tolerance * size, params.ransac_tolerance * size
    if len(source.keypoints) < 3 or len(target.keypoints) < 3:
        return PairResult([], False, np.zeros((0, 2), int))
    pairs = correspondences(source, target, neighbours=params.neighbours)
    T, inliers = ransac(source, target, pairs, tol=rtol, params=params, rng=rng)
    candidates = []
    for i in _distinct(T, params.candidates, tol=rtol):
        refined = icp(source, target, T[i], tol=tol)
        score, contact, pen = contact_score(source, target, refined, source_scene=source_scene,
                                            target_scene=target_scene, tol=tol, params=params)
        candidates.append(Candidate(refined, score, contact, pen, int(inliers[i])))
    candidates.sort(key=lambda c: -c.score)
    matches = np.zeros((0, 2), int)
    if candidates:
        moved = transform_points(candidates[0].T_target_source, source.keypoints[pairs[:, 0]])
        near = np.linalg.norm(moved - target.keypoints[pairs[:, 1]], axis=1) < rtol
        matches = pairs[near]
    touching = bool(candidates) and candidates[0].score >= params.min_score
    return PairResult(candidates, touching, matches)


__all__ = [
    "Candidate", "PairResult", "RegistrationParams", "contact_score", "correspondences", "icp",
    "kabsch", "ransac", "register_pair",
]
