"""Pairwise registration of two fragments along their fracture surfaces.

1. correspondences: each source keypoint's mate signature (H flipped) against the target's
   signatures (k-d tree), both ways;
2. hypotheses from two correspondences with their normals (a point-pair: two points and
   two opposed normals fix a rigid motion, so a hypothesis needs two good
   correspondences, not three), enumerated among nearby pairs, pruned before any fit by
   the point-pair features (distance, angle between the normals, angles of the normals
   to the chord); fitted by Kabsch; scored by keypoint inliers (near, with opposed
   normals) among probes drawn around the hypothesis;
3. a shortlist of distinct hypotheses given a coarse ICP and a quick contact-minus-
   penetration count; the best few refined by point-to-plane ICP between the two fracture
   surfaces, on pairs with opposed normals only;
4. every candidate scored by contact (source fracture area within a tolerance of the
   target, or of the gap between them when material was lost at the break, normals
   opposed), counted in proportion to the continuity of the object's own surface across
   the seam, minus interpenetration (surface area of either fragment that lies inside the
   other, from Open3D signed distances), over the smaller of the two breaks' areas.

Transforms are ``T_target_source``: they map source coordinates into the target's frame.
Why each step: ``docs/method/registration.md``.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass

import numpy as np

from .features import FractureSurface, mate_signature, offset_surface
from .geometry import (farthest_points, invert_transform, make_transform, rotation_angle_deg, rotation_from_vector,
                       transform_points)
from .planes import planar_patches, plane_placements


@dataclass(frozen=True)
class RegistrationParams:
    """Options of :func:`register_pair`; lengths are fractions of the reference size.

    Parameters
    ----------
    tolerance : contact tolerance after ICP
    ransac_tolerance : inlier distance and rigidity tolerance of the RANSAC hypotheses
    neighbours : signature neighbours per keypoint
    pair_radius : largest distance between the two keypoints of a hypothesis, on each side
    hypotheses : at most this many pairs of correspondences are tested (a random subset)
    max_scored : hypotheses passing the checks that are scored
    shortlist : distinct hypotheses given a quick coarse ICP and contact count
    candidates : of those, the best refined by the full ICP, scored and returned
    normal_angle : degrees: agreement of normal angles within a triple, and the largest
        deviation from exactly opposed normals of an inlier
    penetration_weight : penalty per unit of interpenetrating area against contact area
    min_score : below it the verdict is "these two do not touch" (a share of the smaller
        break, :func:`contact_score`)
    noise_tolerance : the contact tolerance is at least this many standard deviations of
        the gap between two surfaces with the set's vertex noise (:func:`with_noise`)
    consensus_pool : hypotheses kept after the first, coarse consensus count for the finer one
    gap : mating surfaces are this far apart (material lost at the break: worn or chipped
        edges, a scan that missed a layer); contact is counted at this distance, within
        ``tolerance``, and ICP keeps it (:func:`set_gap` measures it from the data)
    plane_consensus : a RANSAC inlier must also lie within ``tolerance`` of the target
        keypoint's tangent plane, not only within ``ransac_tolerance`` of it (:func:`ransac`)
    shell_shortlist, shell_consensus_pool : ``shortlist`` and ``consensus_pool`` of
        thin-walled sherds (:func:`pairs.registration_params`)
    shell_whole : sherds' hypotheses ranked best by the consensus of the whole fragment
        (not only around their anchors) that go to the shortlist first, which grows by as
        many (:func:`_consensus`)
    probe_radius : consensus probes are drawn within this multiple of ``pair_radius`` of a
        hypothesis' anchor keypoint
    probes, shell_probes : probes of the first consensus count of every hypothesis (solids,
        sherds); fine_probes : of the second, for the best ``consensus_pool``
    quick_samples, quick_surface_samples : fracture samples of the shortlist's quick ICP and
        contact count, and surface samples of its penetration count
    quick_iterations, quick_level : iterations of the quick ICP, at a distance threshold of
        ``quick_level`` x ``tolerance``; quick_contact : contact distance of the quick count,
        a multiple of ``tolerance``
    refinements : up to this many times ``candidates`` shortlisted poses get the full ICP
    plane_area : planar break faces carrying at least this share of a fragment's fracture
        area also give placements by construction (:mod:`planes`), beside the signature
        hypotheses; 0 turns them off
    plane_candidates : candidates from those placements, beside ``candidates``
    seam_angle : degrees: along a contact, original surface of one fragment continues the
        other's when their normals agree within this (:func:`seam_continuity`); a placement's
        contact counts in proportion to the share that does. 0 turns it off
    break_floor : a fragment's break counts as at least this share of its whole area when
        scores are normalised (a segmentation that found little of a break must not make any
        contact with it look like a closed break)
    rim_reach : the full ICP's finest step also aligns the two rims within this multiple of
        ``tolerance`` (:func:`icp`; 0: contact alone); rim_weight : their rows' weight in all,
        as a share of the contact rows' 
    """

    tolerance: float = 0.006
    ransac_tolerance: float = 0.02
    neighbours: int = 3
    pair_radius: float = 0.1
    hypotheses: int = 200000
    max_scored: int = 6000
    shortlist: int = 30
    candidates: int = 5
    normal_angle: float = 30.0
    penetration_weight: float = 2.0
    min_score: float = 0.06
    noise_tolerance: float = 2.5
    consensus_pool: int = 300
    gap: float = 0.0
    plane_consensus: bool = True
    shell_shortlist: int = 100
    shell_consensus_pool: int = 2000
    shell_whole: int = 25
    probe_radius: float = 2.0
    probes: int = 64
    shell_probes: int = 32
    fine_probes: int = 256
    quick_samples: int = 1000
    quick_surface_samples: int = 500
    quick_iterations: int = 5
    quick_level: float = 3.0
    quick_contact: float = 1.5
    refinements: int = 2
    plane_area: float = 0.05
    plane_candidates: int = 2
    seam_angle: float = 15.0
    break_floor: float = 0.03
    rim_reach: float = 3.0
    rim_weight: float = 0.1


def with_noise(params: RegistrationParams, *, noise: float, size: float) -> RegistrationParams:
    """``params`` with the contact tolerance raised to cover vertex noise.

    Two mating surfaces that each carry vertex noise of standard deviation ``noise`` (mesh
    units) lie a gap of sigma ``sqrt(2) noise`` apart: with a tolerance below that, true
    contact goes uncounted and noise spikes count as interpenetration, which pushes mates
    apart. Noise-free sets keep ``tolerance``.
    """
    tolerance = max(params.tolerance, params.noise_tolerance * np.sqrt(2.0) * noise / size)
    return dataclasses.replace(params, tolerance=float(tolerance))


@dataclass
class Candidate:
    """One registration of a pair.

    Attributes
    ----------
    T_target_source : (4, 4) maps source coordinates into the target frame
    score : (seam continuity · contact − weight · penetration) / the smaller break's area
        (:func:`contact_score`)
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
    radius: float,
    params: RegistrationParams,
    rng: np.random.Generator,
    plane_tol: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Hypotheses from pairs of correspondences: (h, 4, 4) transforms and (h,) inlier counts, best first.

    The pairs of correspondences are enumerated, not drawn: all whose source keypoints and
    whose target keypoints both lie within ``radius`` of each other (a k-d tree on the
    6-d concatenation, Chebyshev metric). A small contact holds only a handful of true
    correspondences among thousands; random draws of two would almost never hit two of them.

    A probe keypoint is an inlier within ``tol`` of a target keypoint with an opposed normal
    and, with ``plane_tol`` (the contact tolerance), within that of the target keypoint's
    tangent plane: two rough breaks held face to face in a wrong pose still have most
    keypoints within ``tol`` of each other (the keypoint spacing sets ``tol``), but only
    mates lie on each other's surface.
    """
    from scipy.spatial import cKDTree

    if len(pairs) < 2:
        return np.zeros((0, 4, 4)), np.zeros(0, int)
    pick = pair_candidates(source, target, pairs, radius=radius)
    if len(pick) > params.hypotheses:
        pick = pick[np.sort(rng.choice(len(pick), params.hypotheses, replace=False))]
    if len(pick) == 0:
        return np.zeros((0, 4, 4)), np.zeros(0, int)
    a = source.keypoints[pairs[pick, 0]]
    b = target.keypoints[pairs[pick, 1]]
    na = source.keypoint_normals[pairs[pick, 0]]
    nb = -target.keypoint_normals[pairs[pick, 1]]  # mating normals are opposed
    ok, da = point_pairs_agree(a, b, na, nb, tol=tol, normal_angle=params.normal_angle)
    angle = np.radians(params.normal_angle)
    idx = np.flatnonzero(ok)
    if len(idx) > params.max_scored:
        idx = np.sort(rng.choice(idx, params.max_scored, replace=False))
    if len(idx) == 0:
        return np.zeros((0, 4, 4)), np.zeros(0, int)
    # two points and their normals (as points one chord length out) fix the rigid motion
    lever = da[idx, None, None]
    T = kabsch(np.concatenate([a[idx], a[idx] + lever * na[idx]], axis=1),
               np.concatenate([b[idx], b[idx] + lever * nb[idx]], axis=1))
    cos_tol = np.cos(angle)
    rotated = np.einsum("hij,hkj->hki", T[:, :3, :3], na[idx])
    facing = np.all(np.einsum("hki,hki->hk", rotated, nb[idx]) > cos_tol, axis=1)
    T = T[facing]
    if len(T) == 0:
        return T, np.zeros(0, int)
    # consensus near the hypothesis: probes drawn around its first source keypoint. Counted
    # over the whole fragment, a true contact of 5-10 % of the fracture surface scores no
    # better than chance overlaps of the rest
    anchors = pairs[pick[idx[facing], 0], 0]
    hoods = _neighbourhoods(source.keypoints, anchors, params.probe_radius * radius)
    return _consensus(T, anchors, source, target, cKDTree(target.keypoints), hoods, tol=tol, cos_tol=cos_tol,
                      params=params, first=params.probes, rng=rng, plane_tol=plane_tol)


def _consensus(T, anchors, source, target, tree, hoods, *, tol, cos_tol, params, first: int, rng, plane_tol=None,
               whole: int = 0):
    """Hypotheses ranked by probe inliers around their anchors (:func:`_inliers`): ``first``
    probes for all, 256 for the best ``params.consensus_pool``; (h, 4, 4) and (h,), best first.

    With ``whole`` > 0, the ``whole`` best by the same counts on keypoints spread over the
    whole source (:func:`geometry.farthest_points`) join the pool and go first, then the
    pool in its local order (the same as without them).

    Notes
    -----
    Around its anchor, a placement that slides a smooth strip along its mate, or along any
    smooth strip of the other fragment (a vessel's own rim), fits as well as the true one:
    on a sherd with a smooth break hundreds of hypotheses have every one of 256 local probes
    in, and the true ones rank below them. Along the whole break only the true placement
    keeps fitting, so the whole-fragment count ranks it near the top. It is no ranking of its
    own: rims and bases are strips too, and a wrong placement laying them together can
    outcount the true one, so the local ranking keeps its place behind the few taken from
    the whole. Both measured by ``benchmarks/studies/shell_hypotheses.py``: on a bowl in three
    by smooth cuts the true placements rank 130 and 568 locally, first over the whole
    fragment; on a vase in four, 5-1929 locally and 1-1998 over the whole.
    """
    def count(T, probes):
        if not len(T):
            return np.zeros(0, np.int64)
        # in chunks, so memory stays bounded (two sherds give up to params.hypotheses at once)
        return np.concatenate([_inliers(T[k:k + 20000], source, target, tree, probes[k:k + 20000], tol=tol,
                                        cos_tol=cos_tol, plane_tol=plane_tol) for k in range(0, len(T), 20000)])

    # the same keypoints spread over the whole fragment for every hypothesis: no draws, so
    # the local ranking's random stream is the one it has without them; the farthest-point
    # order is greedy, so the first m of it are the m spread points
    spread_order = farthest_points(source.keypoints, max(first, params.fine_probes)) if whole > 0 else None

    def everywhere(h, m):
        return np.broadcast_to(spread_order[:m], (h, min(m, len(source.keypoints))))

    inliers = count(T, _draw(hoods, anchors, first, rng))
    top = np.argsort(-inliers, kind="stable")[: params.consensus_pool]
    if whole > 0:
        spread = np.argsort(-count(T, everywhere(len(T), first)), kind="stable")
        top = np.concatenate([top, spread[~np.isin(spread, top)][:whole]])
    T, anchors = T[top], anchors[top]
    local = count(T[: params.consensus_pool], _draw(hoods, anchors[: params.consensus_pool], params.fine_probes, rng))
    if whole <= 0:
        best = np.argsort(-local, kind="stable")
        return T[best], local[best]
    # the whole-fragment hypotheses' local counts are drawn after the pool's (the same stream for those)
    inliers = np.concatenate([local, count(T[len(local):], _draw(hoods, anchors[len(local):], params.fine_probes,
                                                                  rng))])
    first_whole = np.argsort(-count(T, everywhere(len(T), params.fine_probes)), kind="stable")[:whole]
    by_local = np.concatenate([np.argsort(-local, kind="stable"),
                               len(local) + np.argsort(-inliers[len(local):], kind="stable")])
    best = np.concatenate([first_whole, by_local[~np.isin(by_local, first_whole)]])
    return T[best], inliers[best]


def frame_hypotheses(
    source: FractureSurface,
    target: FractureSurface,
    *,
    tol: float,
    radius: float,
    params: RegistrationParams,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Hypotheses of two thin-walled fragments from single keypoint pairs: (h, 4, 4), (h,), best first.

    A strip keypoint's frame (strip normal n, break tangent t: :func:`shells.strip_frames`)
    fixes a rigid motion from one correspondence: n onto the mate's -n, t onto its +t or -t.
    Every source keypoint is tried against every target keypoint, both ways round (strip
    signatures do not discriminate: the descriptor balls are wider than the wall), and the
    hypotheses ranked by probe inliers that also agree in the tangent.
    """
    from scipy.spatial import cKDTree

    ns, ts = source.keypoint_normals, source.keypoint_tangents
    nt, tt = target.keypoint_normals, target.keypoint_tangents
    # beyond ``params.hypotheses`` (both signs), a random subset of the source keypoints anchors
    keep = np.arange(len(ns))
    if 2 * len(ns) * len(nt) > params.hypotheses:
        keep = np.sort(rng.choice(len(ns), max(1, params.hypotheses // (2 * len(nt))), replace=False))
    a, b = (g.ravel() for g in np.meshgrid(keep, np.arange(len(nt)), indexing="ij"))
    frame_s = np.stack([ns[a], ts[a], np.cross(ns[a], ts[a])], axis=2)  # columns n, t, n x t
    T = []
    for sign in (1.0, -1.0):
        n2, t2 = -nt[b], sign * tt[b]
        R = np.einsum("hij,hkj->hik", np.stack([n2, t2, np.cross(n2, t2)], axis=2), frame_s)
        Tk = np.tile(np.eye(4), (len(a), 1, 1))
        Tk[:, :3, :3] = R
        Tk[:, :3, 3] = target.keypoints[b] - np.einsum("hij,hj->hi", R, source.keypoints[a])
        T.append(Tk)
    T, anchors = np.concatenate(T), np.concatenate([a, a])
    hoods = _neighbourhoods(source.keypoints, anchors, params.probe_radius * radius)
    return _consensus(T, anchors, source, target, cKDTree(target.keypoints), hoods, tol=tol,
                      cos_tol=np.cos(np.radians(params.normal_angle)), params=params, first=params.shell_probes, rng=rng,
                      whole=params.shell_whole)


def pair_candidates(source: FractureSurface, target: FractureSurface, pairs: np.ndarray, *, radius: float) -> np.ndarray:
    """(p, 2) indices into ``pairs`` of the correspondence pairs whose source keypoints and
    whose target keypoints both lie within ``radius`` of each other."""
    from scipy.spatial import cKDTree

    joint = np.hstack([source.keypoints[pairs[:, 0]], target.keypoints[pairs[:, 1]]])
    return cKDTree(joint).query_pairs(radius, p=np.inf, output_type="ndarray")


def point_pairs_agree(a, b, na, nb, *, tol: float, normal_angle: float) -> tuple[np.ndarray, np.ndarray]:
    """Which of (h, 2, 3) source point pairs ``a`` (normals ``na``) may map onto target pairs
    ``b`` (normals ``nb``, already flipped for a mate): their point-pair features agree (the
    distance within ``tol`` and over 3 ``tol``; the normals' angle and each normal's angle to
    the chord within ``normal_angle`` degrees). Returns (h,) bool and the (h,) source distances."""
    da = np.linalg.norm(a[:, 1] - a[:, 0], axis=1)
    db = np.linalg.norm(b[:, 1] - b[:, 0], axis=1)
    ok = (np.abs(da - db) < tol) & (da > 3 * tol)
    ua = (a[:, 1] - a[:, 0]) / np.maximum(da, 1e-300)[:, None]
    ub = (b[:, 1] - b[:, 0]) / np.maximum(db, 1e-300)[:, None]
    angle = np.radians(normal_angle)

    def ang(x, y):
        return np.arccos(np.clip(np.einsum("hi,hi->h", x, y), -1.0, 1.0))

    ok &= np.abs(ang(na[:, 0], na[:, 1]) - ang(nb[:, 0], nb[:, 1])) < angle
    ok &= np.abs(ang(na[:, 0], ua) - ang(nb[:, 0], ub)) < angle
    ok &= np.abs(ang(na[:, 1], ua) - ang(nb[:, 1], ub)) < angle
    return ok, da


def _neighbourhoods(points: np.ndarray, anchors: np.ndarray, radius: float) -> dict[int, np.ndarray]:
    """{anchor index: indices of the points within ``radius`` of it}."""
    from scipy.spatial import cKDTree

    keys = np.unique(anchors)
    lists = cKDTree(points).query_ball_point(points[keys], r=radius)
    return {int(k): np.asarray(v, dtype=np.int64) for k, v in zip(keys, lists)}


def _draw(hoods: dict[int, np.ndarray], anchors: np.ndarray, m: int, rng: np.random.Generator) -> np.ndarray:
    """(h, m) point indices drawn uniformly (with replacement) from each anchor's neighbourhood."""
    keys = np.fromiter(hoods, dtype=np.int64)
    sizes = np.array([len(hoods[int(k)]) for k in keys])
    flat = np.concatenate([hoods[int(k)] for k in keys])
    start = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    row = np.searchsorted(keys, anchors)  # keys are sorted (np.unique)
    u = rng.random((len(anchors), m))
    return flat[start[row, None] + (u * sizes[row, None]).astype(np.int64)]


def _inliers(T, source, target, tree, probes, *, tol: float, cos_tol: float, plane_tol: float | None = None) -> np.ndarray:
    """(h,) how many of each hypothesis' probe keypoints (h, m) land within ``tol`` of a
    target keypoint with opposed normals (and, on thin walls, parallel break tangents) and,
    with ``plane_tol``, within that of its tangent plane."""
    p, n = source.keypoints[probes], source.keypoint_normals[probes]
    moved = np.einsum("hij,hkj->hki", T[:, :3, :3], p) + T[:, None, :3, 3]
    turned = np.einsum("hij,hkj->hki", T[:, :3, :3], n)
    dist, near = tree.query(moved.reshape(-1, 3), distance_upper_bound=tol)
    hit = np.isfinite(dist)
    if plane_tol is not None:
        off = moved.reshape(-1, 3)[hit] - target.keypoints[near[hit]]
        hit[hit] = np.abs(np.einsum("ij,ij->i", off, target.keypoint_normals[near[hit]])) < plane_tol
    opposed = np.zeros_like(hit)
    opposed[hit] = np.einsum("ij,ij->i", turned.reshape(-1, 3)[hit], target.keypoint_normals[near[hit]]) < -cos_tol
    if source.keypoint_tangents is not None and target.keypoint_tangents is not None:
        tangent = np.einsum("hij,hkj->hki", T[:, :3, :3], source.keypoint_tangents[probes]).reshape(-1, 3)
        opposed[opposed] = np.abs(np.einsum("ij,ij->i", tangent[opposed],
                                            target.keypoint_tangents[near[opposed]])) > cos_tol
    return opposed.reshape(len(T), -1).sum(axis=1)


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


def opposed_neighbours(tree, points: np.ndarray, normals: np.ndarray, target_normals: np.ndarray, *, reach: float,
                       cos_tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Points whose nearest target sample is within ``reach`` and faces them.

    Parameters
    ----------
    tree : cKDTree of the target samples
    points, normals : (k, 3) query points and their unit normals, in the target frame
    target_normals : (t, 3) unit normals of the samples in ``tree``
    reach : largest distance to the nearest sample
    cos_tol : the normals must be opposed within this cosine (dot product below ``-cos_tol``)

    Returns
    -------
    ok : (k,) bool, the points that have such a neighbour
    nearest : (k,) int, the index of each point's nearest sample (``len`` of the tree where none)
    """
    d, j = tree.query(points, distance_upper_bound=reach)
    ok = np.isfinite(d)
    ok[ok] = np.einsum("ij,ij->i", normals[ok], target_normals[j[ok]]) < -cos_tol
    return ok, j


def icp(
    source: FractureSurface, target: FractureSurface, T: np.ndarray, *, tol: float, normal_angle: float = 30.0,
    iterations: int = 10, levels: tuple[float, ...] = (3.0, 2.0, 1.0), tree=None, n_points: int | None = None,
    rim_reach: float = 0.0,
    rim_weight: float = 0.1,
) -> np.ndarray:
    """Point-to-plane ICP of the source fracture samples onto the target's, from ``T``.

    Only pairs with opposed normals count (Open3D's ICP has no such test: on a small contact
    it slid onto the neighbouring fracture faces of the other fragment). Coarse
    to fine: distance thresholds ``levels`` times ``tol``; the first ``n_points`` samples only
    when given (the samples are in random order). With ``rim_reach`` > 0, at the finest
    threshold the two rims (:func:`features.rim_points`) within ``rim_reach`` times it of each
    other are aligned too, across the rim, with ``rim_weight`` times the contact rows' weight
    in all (:func:`rim_pairs`): only once contact has settled, so that a rim mislabelled far
    from its mate's cannot drag a pose out of its basin, and lightly, so that they decide
    only the motions contact leaves free (sliding along a smooth break), not those a rough
    break pins better than labelled rims do.
    """
    return _icp(source, target, T, tol=tol, normal_angle=normal_angle, iterations=iterations, levels=levels,
                tree=tree, n_points=n_points, max_gap=0.0, rim_reach=rim_reach, rim_weight=rim_weight)[0]


RIM_HUBER = 0.25  # rim offsets beyond this many contact tolerances weigh as 1/offset (Huber)
ICP_RCOND = 1e-4  # ICP leaves the motions whose singular value is under this share of the largest (_solve)


def rim_pairs(points: np.ndarray, directions: np.ndarray, target_points: np.ndarray, target_directions: np.ndarray,
              *, reach: float, tol: float, tree=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rim points matched to a mate's rim, for aligning the two across their common course.

    Parameters
    ----------
    points, directions : (k, 3) rim points and directions across the rim
        (:func:`features.rim_points`), in the target's frame
    target_points, target_directions : (t, 3) the mate's
    reach : largest distance to the matched target rim point (mesh units)
    tol : contact tolerance (mesh units), the scale of the robust weights
    tree : cKDTree of ``target_points``, when already built

    Returns
    -------
    p, q : (m, 3) the matched points and, for each, the nearest target rim point within
        ``reach`` whose direction agrees within 60 degrees
    v : (m, 3) that target point's direction: a row of the fit is the offset ``(p − q)·v``
        (the rims may still slide along their common course)
    weights : (m,) robust weights of those offsets: 1 up to ``RIM_HUBER`` tolerances, then
        falling as 1/offset (a stretch of rim labelled a tolerance or more off its mate's, on
        one side only, must not pull the fit: the offsets' median, not their mean, counts)
    """
    from scipy.spatial import cKDTree

    d, j = (tree if tree is not None else cKDTree(target_points)).query(points, distance_upper_bound=reach)
    ok = np.isfinite(d)
    ok[ok] = np.einsum("ij,ij->i", directions[ok], target_directions[j[ok]]) > 0.5
    p, q, v = points[ok], target_points[j[ok]], target_directions[j[ok]]
    offset = np.abs(np.einsum("ij,ij->i", p - q, v))
    return p, q, v, np.minimum(1.0, RIM_HUBER * tol / np.maximum(offset, 1e-300))


def estimate_gap(
    source: FractureSurface, target: FractureSurface, T: np.ndarray, *, tol: float, max_gap: float,
    normal_angle: float = 30.0,
) -> tuple[np.ndarray, float]:
    """How far apart two mating fracture surfaces are, near the placement ``T``.

    ICP as :func:`icp` with one more unknown, a uniform separation ``g`` in ``[0, max_gap]``
    along the target's normals (residual ``(p − q)·n − g``). Material lost at a break
    leaves the mates offset surfaces of each other, so the fit that closes the gap (what
    plain ICP does) is worse than the one that keeps it.

    Returns
    -------
    T_target_source : (4, 4) the refined placement, ``g`` apart
    gap : float, mesh units
    """
    return _icp(source, target, T, tol=tol, normal_angle=normal_angle, iterations=10, levels=(3.0, 2.0, 1.0),
                tree=None, n_points=None, max_gap=max_gap)


def _icp(source, target, T, *, tol, normal_angle, iterations, levels, tree, n_points, max_gap, rim_reach=0.0,
         rim_weight=0.1):
    """(T, gap): point-to-plane ICP; when ``max_gap`` > 0 the separation (from 0) is a 7th
    unknown, and the source is matched against the target's samples moved out by the
    current separation (nearest points across a wide gap land on the bumps of a rough
    surface, which biases the fit towards a smaller gap). Rims: :func:`icp`."""
    from scipy.spatial import cKDTree

    tree = tree if tree is not None and max_gap == 0 else cKDTree(target.samples)
    # rims only without a separation to fit (its column would shift their rows too)
    rim_tree = (cKDTree(target.rim) if rim_reach > 0 and max_gap == 0 and source.rim is not None
                and target.rim is not None and len(source.rim) >= 6 and len(target.rim) >= 6 else None)
    gap = 0.0
    cos_tol = np.cos(np.radians(normal_angle))
    T = np.array(T, dtype=float, copy=True)
    src, src_n = source.samples[:n_points], source.sample_normals[:n_points]
    for level in levels:
        for _ in range(iterations):
            p = transform_points(T, src)
            n_src = src_n @ T[:3, :3].T
            ok, j = opposed_neighbours(tree, p, n_src, target.sample_normals, reach=level * tol, cos_tol=cos_tol)
            if np.count_nonzero(ok) < (7 if max_gap > 0 else 6):
                return T, gap
            n = target.sample_normals[j[ok]]
            p, q = p[ok], target.samples[j[ok]] + gap * n
            # turns about the contact's centre, in length units (x[:3] times the contact's
            # RMS radius): the columns are then comparable, and a motion the contact leaves
            # (nearly) free can be told by its singular value, whatever the fragment's pose
            centre = p.mean(axis=0)
            radius = max(float(np.sqrt(np.mean(np.sum((p - centre) ** 2, axis=1)))), 1e-300)
            A = np.hstack([np.cross(p - centre, n) / radius, n])
            b = -np.einsum("ij,ij->i", p - q, n)
            if rim_tree is not None and level == levels[-1]:
                pr, qr, v, weights = rim_pairs(transform_points(T, source.rim), source.rim_directions @ T[:3, :3].T,
                                               target.rim, target.rim_directions, reach=rim_reach * level * tol,
                                               tol=tol, tree=rim_tree)
                if len(pr) >= 6:  # rim_weight times the contact rows' weight in all
                    w = np.sqrt(rim_weight * len(A) * weights / weights.sum())
                    A = np.vstack([A, w[:, None] * np.hstack([np.cross(pr - centre, v) / radius, v])])
                    b = np.concatenate([b, -w * np.einsum("ij,ij->i", pr - qr, v)])
            moved = 0.0
            if max_gap > 0:  # the separation grows by x[6]: (p - q) n + A x - x[6] = 0
                x = _solve(np.hstack([A, -np.ones((len(A), 1))]), b)
                new = float(np.clip(gap + x[6], 0.0, max_gap))
                if new != gap + x[6]:
                    x = _solve(A, b + (new - gap))
                moved, gap = abs(new - gap), new
                tree = cKDTree(target.samples + gap * target.sample_normals)
            else:
                x = _solve(A, b)
            x[:3] /= radius
            R = rotation_from_vector(x[:3])
            T = make_transform(R, x[3:6] + centre - R @ centre) @ T
            if np.linalg.norm(x[:3]) < 1e-7 and np.linalg.norm(x[3:6]) < 1e-6 * tol and moved < 1e-6 * tol:
                break
    return T, gap


def _solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The least-squares step of ICP, with the motions the contact leaves (nearly) free
    left alone.

    Notes
    -----
    A contact that does not pin every motion (a planar face slides in its plane, a narrow
    sherd's strip along a smoothly curved break) has singular values near zero; the
    minimum-norm solution then turns the sampling's own tiny residuals into steps of
    several tolerances along those motions, and from the true pose of a vessel's sherds
    ICP walked off most of the contact (``tests/test_shells.py``). Truncating the small
    singular values (``ICP_RCOND``, relative to the largest, turns in length units) keeps
    such a motion where the hypothesis put it, unless the rims' rows pin it.
    """
    return np.linalg.lstsq(A, b, rcond=ICP_RCOND)[0]


def _within(points: np.ndarray, surf: FractureSurface, tol: float) -> np.ndarray:
    """(p,) bool: inside ``surf``'s bounding box grown by the tolerance and the sample spacing
    (points outside can neither touch it nor be inside it)."""
    margin = tol + 2.0 * np.sqrt(surf.surface_area)
    lo, hi = surf.surface.min(axis=0) - margin, surf.surface.max(axis=0) + margin
    return np.all((points >= lo) & (points <= hi), axis=1)


def touching_samples(
    source: FractureSurface,
    target: FractureSurface,
    T_target_source: np.ndarray,
    *,
    target_scene,
    tol: float,
    normal_angle: float,
    gap: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Which fracture samples of ``source`` touch ``target`` at a placement, and where.

    A sample touches when its distance to the target's surface is within ``tol`` of
    ``gap`` (the separation of the mates; 0 unless material was lost at the break) and its
    normal opposes the target's there (within ``normal_angle`` degrees).

    Returns
    -------
    touching : (s,) bool over ``source.samples``
    closest : (t, 3) the closest target points (target coordinates) of the t touching samples
    """
    import open3d as o3d

    moved = transform_points(T_target_source, source.samples)
    touching = np.zeros(len(moved), bool)
    near = np.flatnonzero(_within(moved, target, tol + gap))
    if len(near) == 0:
        return touching, np.zeros((0, 3))
    closest = target_scene.compute_closest_points(o3d.core.Tensor(moved[near].astype(np.float32)))
    points = closest["points"].numpy().astype(np.float64)
    dist = np.linalg.norm(points - moved[near], axis=1)
    turned = source.sample_normals[near] @ T_target_source[:3, :3].T
    opposed = np.einsum("ij,ij->i", turned, closest["primitive_normals"].numpy()) < -np.cos(np.radians(normal_angle))
    hit = (np.abs(dist - gap) < tol) & opposed
    touching[near[hit]] = True
    return touching, points[hit]


def contact_score(
    source: FractureSurface,
    target: FractureSurface,
    T_target_source: np.ndarray,
    *,
    source_scene,
    target_scene,
    tol: float,
    params: RegistrationParams,
    gap: float = 0.0,
) -> tuple[float, float, float]:
    """(score, contact area, penetration area) of a placement; ``gap`` (mesh units) as in
    :func:`touching_samples`. The score is seam continuity x contact minus
    ``penetration_weight`` x penetration, over the smaller break's area (:func:`_score_area`).

    Only points inside the other fragment's bounding box (grown by the tolerance and the
    sample spacing) are queried: the others can neither touch nor be inside it.
    """
    touching, _ = touching_samples(source, target, T_target_source, target_scene=target_scene, tol=tol,
                                   normal_angle=params.normal_angle, gap=gap)
    contact = float(np.count_nonzero(touching)) * source.sample_area
    # penetration both ways: whole-surface samples deeper than the tolerance inside the other
    s_in_t = transform_points(T_target_source, source.surface)
    t_in_s = transform_points(invert_transform(T_target_source), target.surface)
    penetration = (_inside(target_scene, s_in_t[_within(s_in_t, target, tol)], tol) * source.surface_area
                   + _inside(source_scene, t_in_s[_within(t_in_s, source, tol)], tol) * target.surface_area)
    smaller = _score_area(source, target, floor=params.break_floor)
    seam = seam_continuity(source, target, T_target_source, transform_points(T_target_source, source.samples[touching]),
                           source_scene=source_scene, target_scene=target_scene, tol=tol, params=params)
    return float((seam * contact - params.penetration_weight * penetration) / smaller), contact, penetration


def _score_area(source: FractureSurface, target: FractureSurface, *, floor: float) -> float:
    """The area a pair's score is a share of: the smaller of the two breaks (fracture
    areas), each at least ``floor`` of its fragment's whole area.

    Notes
    -----
    A true mate closes a share of the break it meets whatever the object's shape, while its
    share of the whole fragment shrinks with how thin the part is: a flat ring's or a sherd's
    break is 2-7 % of its surface, a compact solid's 15-50 %. Over the break, one threshold
    (``min_score``, ``AssemblyParams.min_gain``) serves all of them.
    """
    return max(min(max(s.fracture_area, floor * s.area) for s in (source, target)), 1e-300)


def seam_continuity(
    source: FractureSurface, target: FractureSurface, T_target_source: np.ndarray, contact: np.ndarray, *,
    source_scene, target_scene, tol: float, params: RegistrationParams, min_samples: int = 8,
) -> float:
    """The share of the original surface along a contact that continues across it.

    Whole-surface samples labelled original within reach of the ``contact`` points (target
    coordinates), on either fragment, that do not themselves touch the other fragment, are
    the seam; a seam sample continues when the other fragment has an original sample within
    1.5 reaches whose normal agrees with its own within ``params.seam_angle``. The reach is twice
    the tolerance, at least 2.5 whole-surface sample spacings. 1.0 (no evidence) when the
    surfaces carry no labelled normals, the check is off, or the seam has fewer than
    ``min_samples`` samples on both sides together.

    Notes
    -----
    Where two fragments were one piece, the object's own surface runs on across the
    break: along the seam it is continuous in position and tangent plane, whatever the
    break's style or roughness, so this holds by construction for every true placement
    (up to the curvature over the reach, and chips). A wrong placement that still closes
    much of a break (a vessel's rim laid on another rim, a sherd turned inside out on a
    slanted break, a cell face slid along its mate) leaves a kink or a step there.
    """
    if params.seam_angle <= 0 or len(contact) == 0 or any(
            s.surface_normals is None or s.surface_original is None for s in (source, target)):
        return 1.0
    reach = max(2.0 * tol, 2.5 * np.sqrt(max(source.surface_area, target.surface_area)))
    T_source_target = invert_transform(T_target_source)
    sides = [(source, target, T_target_source, target_scene, contact),
             (target, source, T_source_target, source_scene, transform_points(T_source_target, contact))]
    continuous, total = 0, 0
    for one, other, T_other_one, other_scene, near_points in sides:
        c, t = _seam_side(one, other, T_other_one, near_points, other_scene=other_scene, reach=reach, tol=tol,
                          params=params)
        continuous, total = continuous + c, total + t
    return float(continuous / total) if total >= min_samples else 1.0


def _seam_side(one, other, T_other_one, contact, *, other_scene, reach, tol, params) -> tuple[int, int]:
    """(continuous, seam samples) of ``one``'s side of a seam (:func:`seam_continuity`),
    in ``other``'s coordinates."""
    import open3d as o3d
    from scipy.spatial import cKDTree

    original = np.flatnonzero(one.surface_original)
    if len(original) == 0:
        return 0, 0
    p = transform_points(T_other_one, one.surface[original])
    near = np.isfinite(cKDTree(contact).query(p, distance_upper_bound=reach)[0])
    if not near.any():
        return 0, 0
    p, n = p[near], one.surface_normals[original[near]] @ T_other_one[:3, :3].T
    # an original sample that touches the other fragment is break the labels missed, not seam
    closest = other_scene.compute_closest_points(o3d.core.Tensor(p.astype(np.float32)))
    dist = np.linalg.norm(closest["points"].numpy() - p, axis=1)
    facing = np.einsum("ij,ij->i", n, closest["primitive_normals"].numpy()) < -np.cos(np.radians(params.normal_angle))
    seam = ~((dist < tol) & facing)
    p, n = p[seam], n[seam]
    q, m = other.surface[other.surface_original], other.surface_normals[other.surface_original]
    if len(p) == 0 or len(q) == 0:
        return 0, len(p)
    # the other side's seam lies up to a reach beyond the contact: look that much farther
    hoods = cKDTree(q).query_ball_point(p, 1.5 * reach)
    counts = np.fromiter(map(len, hoods), np.int64, len(hoods))
    owner = np.repeat(np.arange(len(p)), counts)
    flat = np.fromiter(itertools.chain.from_iterable(hoods), np.int64, int(counts.sum()))
    agree = np.einsum("ij,ij->i", m[flat], n[owner]) > np.cos(np.radians(params.seam_angle))
    return int(np.count_nonzero(np.bincount(owner[agree], minlength=len(p)))), len(p)


def _inside(scene, points: np.ndarray, tol: float) -> int:
    """How many points lie deeper than ``tol`` inside the scene's closed mesh.

    Notes
    -----
    The ray-parity vote first, the distance only for the points inside: Open3D's signed
    distance is the same distance times the same vote, so this counts exactly the points
    whose signed distance is below ``-tol``, at a fraction of the cost (most points of a
    placement are outside).
    """
    import open3d as o3d

    if len(points) == 0:
        return 0
    query = points.astype(np.float32)
    inside = scene.compute_occupancy(o3d.core.Tensor(query)).numpy() > 0.5
    if not inside.any():
        return 0
    return int(np.count_nonzero(scene.compute_distance(o3d.core.Tensor(query[inside])).numpy() > tol))


def contact_relief(
    source: FractureSurface, target: FractureSurface, T: np.ndarray, *, tol: float, gap: float = 0.0,
    normal_angle: float = 30.0,
) -> float:
    """The RMS distance (mesh units) of the contact at ``T`` from its least-squares plane:
    the target samples that a source sample touches (within ``tol`` of ``gap``, normals
    opposed); 0 with fewer than three.

    Notes
    -----
    A separation along the normals and a motion of the source are told apart only by the
    relief of the contact: on a plane, moving the source along the normal is the same as a
    gap, and :func:`estimate_gap` drifts to its bound (a clean cell face with vertex noise
    of 0.1 % of the size read 0.08, the bound, at its true placement). The face normals of
    noisy samples vary, but not the positions: the relief is measured on those.
    """
    _, j = _touching(source, target, T, tol=tol, gap=gap, normal_angle=normal_angle)
    q = target.samples[np.unique(j)]
    if len(q) < 3:
        return 0.0
    centred = q - q.mean(axis=0)
    return float(np.linalg.svd(centred, compute_uv=False)[2] / np.sqrt(len(q)))


def contact_rms(
    source: FractureSurface, target: FractureSurface, T: np.ndarray, *, tol: float, gap: float = 0.0,
    normal_angle: float = 30.0,
) -> float:
    """The RMS of ``(p - q)·n - gap`` (mesh units) over the source samples within ``tol`` of
    ``gap`` from the target at ``T``, normals opposed (q, n the nearest target sample and its
    normal); inf with none."""
    p, j = _touching(source, target, T, tol=tol, gap=gap, normal_angle=normal_angle)
    if len(p) == 0:
        return float("inf")
    n = target.sample_normals[j]
    r = np.einsum("ij,ij->i", p - (target.samples[j] + gap * n), n)
    return float(np.sqrt(np.mean(r * r)))


def _touching(source: FractureSurface, target: FractureSurface, T: np.ndarray, *, tol: float, gap: float,
              normal_angle: float) -> tuple[np.ndarray, np.ndarray]:
    """(p (k, 3), j (k,)): the source samples placed by ``T`` that lie within ``tol`` of the
    target moved out ``gap`` along its normals, normals opposed, and their nearest target samples."""
    from scipy.spatial import cKDTree

    p = transform_points(T, source.samples)
    ok, j = opposed_neighbours(cKDTree(target.samples + gap * target.sample_normals), p,
                               source.sample_normals @ T[:3, :3].T, target.sample_normals, reach=tol,
                               cos_tol=np.cos(np.radians(normal_angle)))
    return p[ok], j[ok]


def set_gap(
    surfaces: list[FractureSurface], pair_results: dict, *, size: float, params: RegistrationParams,
    max_gap: float = 0.08,
) -> float:
    """The separation of mating fracture surfaces over a set, a fraction of ``size``.

    :func:`estimate_gap` from the best candidate of every touching pair; the median,
    weighted by contact area, so a few wrong pairs do not move it. A pair whose contact is
    flat within the contact tolerance (:func:`contact_relief`) cannot tell a gap from a
    motion and does not count. A pair whose surfaces, set that far apart, fit no closer
    than touching (:func:`contact_rms`, within twice the tolerance) counts as no gap.
    0 with no touching pair that counts.

    Notes
    -----
    Where material was lost, the mates are offset surfaces of each other: touching, they
    meet only in part and the residual is of the order of the gap; set apart by it, they
    fit to the noise. On a smooth, curved break with vertex noise the gap and a motion
    along the normal are nearly the same unknown, and the fit can drift to a gap that fits
    worse than touching (``python -m benchmarks.studies.gap_evidence`` gives both
    residuals for puzzles with and without a gap).

    Parameters
    ----------
    surfaces : FractureSurface per fragment
    pair_results : (source, target) -> PairResult, as :func:`register_pair` gives
    size : reference size (mesh units)
    params : the RegistrationParams the pairs were registered with
    max_gap : largest separation considered, a fraction of ``size``
    """
    gaps, weights = [], []
    for (i, j), res in sorted(pair_results.items()):
        if res.touching:
            target, T0, tol = offset_surface(surfaces[j], params.gap * size), res.best.T_target_source, params.tolerance * size
            T, g = estimate_gap(surfaces[i], target, T0, tol=tol, max_gap=max_gap * size, normal_angle=params.normal_angle)
            if contact_relief(surfaces[i], target, T, tol=tol, gap=g, normal_angle=params.normal_angle) <= tol:
                continue
            apart = contact_rms(surfaces[i], target, T, tol=2 * tol, gap=g, normal_angle=params.normal_angle)
            if g > 0 and apart >= contact_rms(surfaces[i], target, T0, tol=2 * tol, normal_angle=params.normal_angle):
                g = 0.0
            gaps.append(g / size + params.gap)
            weights.append(res.best.contact_area)
    if not gaps:
        return 0.0
    order = np.argsort(gaps)
    cum = np.cumsum(np.asarray(weights)[order])
    return float(np.asarray(gaps)[order][np.searchsorted(cum, 0.5 * cum[-1])])


def _quick_ranked(source, target, T, *, tree, source_scene, target_scene, tol: float, rtol: float,
                  params: RegistrationParams, count: int | None = None):
    """[(quick score, hypothesis index, coarse pose)] of the shortlist (``count``, default
    ``params.shortlist``, distinct hypotheses), best first: a quick coarse ICP on
    ``params.quick_samples`` fracture samples, then contact (in proportion to its seam's
    continuity, :func:`seam_continuity`) minus weighted penetration on them."""
    cos_tol = np.cos(np.radians(params.normal_angle))
    quick = []
    n, m = params.quick_samples, params.quick_surface_samples
    for i in _distinct(T, params.shortlist if count is None else count, tol=rtol):
        coarse = icp(source, target, T[i], tol=tol, normal_angle=params.normal_angle, iterations=params.quick_iterations,
                     levels=(params.quick_level,), tree=tree, n_points=n)
        p = transform_points(coarse, source.samples[:n])
        ok, _ = opposed_neighbours(tree, p, source.sample_normals[:n] @ coarse[:3, :3].T, target.sample_normals,
                                   reach=params.quick_contact * tol, cos_tol=cos_tol)
        inside = _inside(target_scene, transform_points(coarse, source.surface[:m]), tol)
        seam = seam_continuity(source, target, coarse, p[ok], source_scene=source_scene, target_scene=target_scene,
                               tol=tol, params=params)
        # the same units as the full score: contact minus weighted penetration, as areas
        quick.append((seam * ok.sum() * source.sample_area * len(source.samples) / n
                      - params.penetration_weight * inside * source.surface_area * len(source.surface) / m, i, coarse))
    quick.sort(key=lambda q: -q[0])
    return quick


def _plane_hypotheses(source: FractureSurface, target: FractureSurface, *, tol: float, params: RegistrationParams,
                      rng: np.random.Generator) -> np.ndarray:
    """(h, 4, 4) placements laying a planar break face of the source on one of the target's
    (:func:`planes.plane_placements`); none when either has no plane of ``params.plane_area``."""
    if params.plane_area <= 0 or source.fracture_area <= 0 or target.fracture_area <= 0:
        return np.zeros((0, 4, 4))
    # a child generator: the planes draw no numbers from the RANSAC's stream
    local = rng.spawn(1)[0]
    found = [planar_patches(s.samples, s.sample_normals, s.sample_area, tol=tol,
                            min_area=params.plane_area * s.fracture_area, rng=local) for s in (source, target)]
    return plane_placements(*found)


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
    tol, rtol, gap = params.tolerance * size, params.ransac_tolerance * size, params.gap * size
    if len(source.keypoints) < 3 or len(target.keypoints) < 3:
        return PairResult([], False, np.zeros((0, 2), int))
    # with a gap, the source mates with the target's surface moved out by it (signatures,
    # and the mesh for penetration, stay the target's own)
    target = offset_surface(target, gap)
    pairs = correspondences(source, target, neighbours=params.neighbours)
    if source.keypoint_tangents is not None and target.keypoint_tangents is not None:
        T, inliers = frame_hypotheses(source, target, tol=rtol, radius=params.pair_radius * size, params=params,
                                      rng=rng)
    else:
        T, inliers = ransac(source, target, pairs, tol=rtol, radius=params.pair_radius * size, params=params,
                            rng=rng, plane_tol=tol if params.plane_consensus else None)
    candidates = []
    # a shortlist gets a quick coarse ICP on a thousand samples and a quick contact count;
    # the best of those the full ICP and score (the true pose of a small contact can rank
    # far down the hypotheses)
    from scipy.spatial import cKDTree

    tree = cKDTree(target.samples)
    quick = _quick_ranked(source, target, T, tree=tree, source_scene=source_scene, target_scene=target_scene, tol=tol,
                          rtol=rtol, params=params)
    flat = _plane_hypotheses(source, target, tol=tol, params=params, rng=rng)
    # placements by construction (index -1: no RANSAC inliers) have slots of their own: two
    # planar faces of other fragments, laid together, touch over as much as true mates do
    laid = [(q, -1, coarse) for q, _, coarse in _quick_ranked(
        source, target, flat, tree=tree, source_scene=source_scene, target_scene=target_scene, tol=tol, rtol=rtol,
        params=params, count=len(flat))] if len(flat) else []
    laid.sort(key=lambda q: -q[0])
    # different hypotheses often converge to one pose: keep distinct ones, so the
    # assembly gets real alternatives (up to twice as many refinements as candidates)
    for ranked, slots in ((quick, params.candidates), (laid, params.plane_candidates)):
        added = 0
        for _, i, coarse in ranked[: params.refinements * slots]:
            if added == slots:
                break
            refined = icp(source, target, coarse, tol=tol, normal_angle=params.normal_angle, tree=tree,
                          rim_reach=params.rim_reach, rim_weight=params.rim_weight)
            if _distinct(np.array([c.T_target_source for c in candidates] + [refined]), len(candidates) + 1,
                         tol=rtol)[-1:] != [len(candidates)]:
                continue
            score, contact, pen = contact_score(source, target, refined, source_scene=source_scene,
                                                target_scene=target_scene, tol=tol, params=params, gap=gap)
            candidates.append(Candidate(refined, score, contact, pen, int(inliers[i]) if i >= 0 else 0))
            added += 1
    candidates.sort(key=lambda c: -c.score)
    matches = np.zeros((0, 2), int)
    if candidates:
        moved = transform_points(candidates[0].T_target_source, source.keypoints[pairs[:, 0]])
        near = np.linalg.norm(moved - target.keypoints[pairs[:, 1]], axis=1) < rtol
        matches = pairs[near]
    touching = bool(candidates) and bool(candidates[0].score >= params.min_score)
    return PairResult(candidates, touching, matches)


__all__ = [
    "Candidate", "PairResult", "RegistrationParams", "contact_rms", "contact_score", "correspondences", "estimate_gap", "frame_hypotheses", "contact_relief", "icp",
    "kabsch", "opposed_neighbours", "ransac", "register_pair", "rim_pairs", "seam_continuity", "set_gap", "touching_samples",
    "with_noise",
]
