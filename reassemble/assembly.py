"""Global assembly: from ranked pairwise candidates to one pose per fragment.

1. greedy merging of sub-assemblies (after Huang et al. 2006): every candidate placement
   of a pair proposes to merge the two sub-assemblies holding its fragments; a proposal
   is verified on *all* fragment pairs it brings together (loop verification: where two
   sub-assemblies touch in several places, every contact adds to the gain and any
   interpenetration rejects it), and the best verified proposal is merged first;
2. joint refinement of all poses of a sub-assembly: point-to-plane least squares over
   every contact at once, so loop errors are spread instead of piled on the last piece;
3. per fragment a confidence (share of its fracture surface in contact with its placed
   neighbours) and per contact the score, contact and penetration areas.

A fragment whose best proposal does not verify stays alone: ``placed`` false, never forced in.
Poses are ``T_group_fragment`` within each sub-assembly; the largest sub-assembly (by area)
is group 0, and its largest fragment is the world frame.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .features import FractureSurface, same_surface
from .geometry import (face_normals, farthest_points, invert_transform, make_scene, rotation_from_vector,
                       transform_points)
from .parallel import pool_map, worker_state
from .registration import RegistrationParams, contact_score, opposed_neighbours, rim_pairs, touching_samples


@dataclass(frozen=True)
class AssemblyParams:
    """Options of :func:`assemble`; lengths are fractions of the reference size.

    Parameters
    ----------
    candidates : candidate placements per pair that may propose a merge (registration gives
        up to ``RegistrationParams.candidates + plane_candidates``)
    min_gain : a merge needs at least this verified gain (sum of the pair scores it creates,
        each a share of the smaller break: :func:`registration.contact_score`)
    max_penetration : a merge is rejected when any two fragments it brings together
        interpenetrate by more than this share of the smaller one's surface area
    refine_iterations : joint point-to-plane iterations per coarse level of :func:`refine`
    refine_max_iterations : at most this many at its finest level, which ends when converged:
        no fragment's samples moving more than ``refine_stop`` times the contact tolerance
    group_rounds : rounds of registering whole sub-assemblies against each other
    starts : greedy merging is run from this many first merges (the best proposals of two
        lone fragments, in order) and the outcome with the largest verified total kept
        (:func:`_merge_from_starts`); 1: plain greedy
    verify_samples : samples per fragment when verifying a merge
    refine_levels : distance thresholds of the joint refinement, coarse to fine, multiples of
        the contact tolerance (:func:`refine`); refine_samples : fracture samples per fragment it uses
    rim_reach : the refinement's finest level also aligns the rims of touching fragments within
        this multiple of its threshold (0: contact alone; :func:`refine`); rim_weight : their
        rows' weight in all, as a share of the contact rows' 
    world_gap : space between the main assembly and the other sub-assemblies in the world
        frame (:func:`world_poses`)
    touching_points : touching points kept per contact, for the pictures (:func:`contact_points`)
    """

    candidates: int = 7
    min_gain: float = 0.06
    max_penetration: float = 0.02
    refine_iterations: int = 15
    refine_max_iterations: int = 100
    refine_stop: float = 0.01
    group_rounds: int = 3
    starts: int = 4
    verify_samples: int = 1000
    refine_levels: tuple[float, ...] = (2.0, 1.0)
    refine_samples: int = 1500
    rim_reach: float = 3.0
    rim_weight: float = 0.1
    world_gap: float = 0.1
    touching_points: int = 40


@dataclass(frozen=True)
class Contact:
    """Two fragments touching in the final assembly (``a`` < ``b``, indices)."""

    a: int
    b: int
    score: float
    contact_area: float
    penetration_area: float


@dataclass
class Assembly:
    """Result of :func:`assemble` for n fragments.

    Attributes
    ----------
    T_group_fragment : (n, 4, 4) pose of each fragment in its sub-assembly's frame
    group : (n,) int, sub-assembly of each fragment; 0 is the largest by area
    placed : (n,) bool, in group 0 together with at least one other fragment
    confidence : (n,) float in [0, 1], share of the fracture area in contact with the
        fragment's neighbours in its group (0 for a fragment alone)
    contacts : list[Contact] of touching pairs within the sub-assemblies
    merges : list of (source, target, gain) in the order merged
    """

    T_group_fragment: np.ndarray
    group: np.ndarray
    placed: np.ndarray
    confidence: np.ndarray
    contacts: list[Contact] = field(default_factory=list)
    merges: list[tuple[int, int, float]] = field(default_factory=list)


def _spheres(surfaces: list[FractureSurface]) -> tuple[np.ndarray, np.ndarray]:
    """Bounding-sphere centres (n, 3) and radii (n,) of the fragments' surface samples."""
    centres = np.array([s.surface.mean(axis=0) for s in surfaces])
    radii = np.array([np.linalg.norm(s.surface - c, axis=1).max() for s, c in zip(surfaces, centres)])
    return centres, radii


def _ball(points: np.ndarray) -> tuple[np.ndarray, float]:
    """(centre (3,), radius) of a ball holding every one of ``points`` (k, 3)."""
    if not len(points):
        return np.zeros(3), 0.0
    centre = points.mean(axis=0)
    return centre, float(np.linalg.norm(points - centre, axis=1).max())


def _near(T_p: np.ndarray, T_q: np.ndarray, p: int, q: int, centres, radii, margin: float) -> bool:
    """Whether fragments p and q, posed in a common frame, may touch."""
    cp = T_p[:3, :3] @ centres[p] + T_p[:3, 3]
    cq = T_q[:3, :3] @ centres[q] + T_q[:3, 3]
    return float(np.linalg.norm(cp - cq)) <= radii[p] + radii[q] + margin


def _thinned(surface: FractureSurface, count: int) -> FractureSurface:
    """The same surface with at most ``count`` samples of each kind (the first: they are in random order)."""
    q, p = min(count, len(surface.samples)), min(count, len(surface.surface))
    return dataclasses.replace(
        surface, samples=surface.samples[:q], sample_normals=surface.sample_normals[:q],
        sample_area=surface.sample_area * len(surface.samples) / max(q, 1),
        surface=surface.surface[:p], surface_area=surface.surface_area * len(surface.surface) / max(p, 1),
        surface_normals=None if surface.surface_normals is None else surface.surface_normals[:p],
        surface_original=None if surface.surface_original is None else surface.surface_original[:p])


def _evaluate(pairs, poses, surfaces, scenes, *, tol, reg_params, centres, radii, cache, gap=0.0):
    """Pair scores (score, contact, penetration) of the given fragment pairs at the given poses."""
    out = {}
    for p, q in pairs:
        if not _near(poses[p], poses[q], p, q, centres, radii, tol + gap):
            continue
        T_q_p = invert_transform(poses[q]) @ poses[p]
        key = (p, q, np.round(T_q_p, 9).tobytes())
        if key not in cache:
            cache[key] = contact_score(surfaces[p], surfaces[q], T_q_p, source_scene=scenes[p],
                                       target_scene=scenes[q], tol=tol, params=reg_params, gap=gap)
        out[(p, q)] = cache[key]
    return out


def _cycle_support(proposals, surfaces, *, reach: float, points: int = 32) -> np.ndarray:
    """Per proposal (i, j, T_j_i, score), the support of third fragments: over every other
    fragment k, the best min(score) of a proposal of (i, k) and one of (k, j) whose
    composition places i where the proposal does (``points`` of i's samples within
    ``reach``, mesh units); (p,) floats.

    Notes
    -----
    Two fragments placed right place a third that touches both consistently, whatever the
    object: the three true relative poses close a loop. A wrong pose that outscores the
    truth (a vessel's rim laid on another rim, a cell face slid along its mate) is rarely
    closed by two other pairs' candidates, while a true one is wherever a third fragment
    meets both: the loop closure of Huang et al. 2006 (Sec. 6), here as a merge's priority
    before the merge is verified.
    """
    rel: dict[tuple[int, int], list[tuple[np.ndarray, float]]] = {}
    for i, j, T, s in proposals:
        rel.setdefault((i, j), []).append((T, s))
        rel.setdefault((j, i), []).append((invert_transform(T), s))
    stacked = {key: (np.array([T for T, _ in v]), np.array([s for _, s in v])) for key, v in rel.items()}
    others: dict[int, set[int]] = {}
    for i, k in rel:
        others.setdefault(i, set()).add(k)
    support = np.zeros(len(proposals))
    by_pair: dict[tuple[int, int], list[int]] = {}
    for x, (i, j, _, _) in enumerate(proposals):
        by_pair.setdefault((i, j), []).append(x)
    for (i, j), xs in by_pair.items():
        pts = surfaces[i].surface[:points]
        targets = np.array([transform_points(proposals[x][2], pts) for x in xs])  # (c, p, 3)
        # the compositions through k are the same for every proposal of (i, j)
        for k in sorted(others.get(i, set()) & others.get(j, set()) - {i, j}):
            (A, sa), (B, sb) = stacked[(i, k)], stacked[(k, j)]
            C = np.einsum("bij,ajk->baik", B, A)  # (b, a, 4, 4) T_j_k @ T_k_i
            moved = np.einsum("baij,pj->bapi", C[..., :3, :3], pts) + C[:, :, None, :3, 3]
            agree = np.linalg.norm(moved[None] - targets[:, None, None], axis=-1).max(axis=-1) <= reach  # (c, b, a)
            both = np.where(agree, np.minimum.outer(sb, sa)[None], -np.inf).max(axis=(1, 2))
            for x, best in zip(xs, both):
                if best > -np.inf:
                    support[x] += float(best)
    return support


def _merge_from_starts(proposals, state, *, starts: int, common: dict):
    """Greedy merging (:func:`_merge`) from up to ``starts`` first merges, in place on
    ``state``: the outcome whose sub-assemblies have the largest verified total (the sum of
    the scores of every two fragments placed together, :func:`_total`); returns its merges.

    Notes
    -----
    Greedy merging commits to the best-scored pair first. A placement that keeps full
    contact while sliding or turning on its mate (a round or near-planar break face) can
    outscore the true one by a little, and a wrong first merge then rules out the loop
    that the true poses close: the third fragment can no longer touch both. The true
    assembly closes every loop, so every contact of the object adds to its total, whatever
    the break; a wrong start loses at least the contacts it prevents. The starts are the
    best first merges in greedy order (the first is plain greedy, kept on a tie). Huang et
    al. 2006 (Sec. 6) search the space of consistent merges the same way, by verified
    contact over the loops.
    """
    group, poses, members = state
    support = _cycle_support(proposals, common["surfaces"], reach=common["reach"])
    lone = [x for x, (i, j, _, _) in enumerate(proposals) if len(members[group[i]]) == 1 and
            len(members[group[j]]) == 1 and group[i] != group[j]]
    firsts = sorted(lone, key=lambda x: (-(proposals[x][3] + support[x]), x))[: max(1, starts)]
    if len(firsts) < 2:
        return _merge(proposals, state, support=support, **common)
    best = None
    for x in firsts:
        trial = (group.copy(), poses.copy(), {g: list(m) for g, m in members.items()})
        i, j, T_j_i, score = proposals[x]
        _join(trial, i, j, T_j_i)
        merges = [(i, j, float(score))] + _merge(proposals, trial, support=support, **common)
        total = _total(trial, **common)
        if best is None or total > best[0] + 1e-9:
            best = (total, trial, merges)
    _, (g, p, m), merges = best
    group[:], poses[:] = g, p
    members.clear()
    members.update(m)
    return merges


def _total(state, *, surfaces, scenes, tol, reg_params, centres, radii, cache, gap, **_) -> float:
    """The sum of the verified scores of every two fragments in one sub-assembly."""
    group, poses, members = state
    pairs = [pq for g in members.values() for pq in itertools.combinations(sorted(g), 2)]
    scores = _evaluate(pairs, poses, surfaces, scenes, tol=tol, reg_params=reg_params, centres=centres, radii=radii,
                       cache=cache, gap=gap)
    return float(sum(s for s, _, _ in scores.values()))


def _merge(proposals, state, *, surfaces, scenes, areas, tol, reach, params, reg_params, centres, radii, cache, gap,
           support=None):
    """Greedy verified merging (in place on ``state``); returns the merges made.

    Two lone fragments' merge is ranked by its pair score plus the support of the loops
    that close through it (:func:`_cycle_support`, or ``support`` given for these
    proposals); any other merge by its verified gain.
    """
    group, poses, members = state
    merges = []
    if support is None:
        support = _cycle_support(proposals, surfaces, reach=reach)
    # a proposal's verdict holds while its two sub-assemblies stay as they are: only those
    # touching the last merge's are weighed again (lazy greedy; the same merges, in order)
    stamp = {g: 0 for g in members}
    verdicts: dict[int, tuple] = {}  # proposal -> (groups, stamps, ok, gain, priority)
    while True:
        best = None
        for x, (i, j, T_j_i, score) in enumerate(proposals):
            a, b = group[i], group[j]
            if a == b:
                continue
            seen = verdicts.get(x)
            if seen is not None and seen[0] == (a, b) and seen[1] == (stamp[a], stamp[b]):
                ok, gain, priority = seen[2:]
            else:
                ok, gain, priority = _weigh(x, proposals[x], state, support, surfaces=surfaces, scenes=scenes,
                                            areas=areas, tol=tol, params=params, reg_params=reg_params,
                                            centres=centres, radii=radii, cache=cache, gap=gap)
                verdicts[x] = ((a, b), (stamp[a], stamp[b]), ok, gain, priority)
            if ok and gain >= params.min_gain and (best is None or priority > best[0]):
                best = (priority, gain, i, j, T_j_i)
        if best is None:
            return merges
        _, gain, i, j, T_j_i = best
        stamp[_join(state, i, j, T_j_i)] += 1
        merges.append((i, j, float(gain)))


def _join(state, i: int, j: int, T_j_i: np.ndarray) -> int:
    """Merge the sub-assembly of ``i`` into that of ``j`` (in place on ``state``), placing
    ``i`` at ``T_j_i`` from ``j``; returns the sub-assembly that grew."""
    group, poses, members = state
    a, b = group[i], group[j]
    T_b_a = poses[j] @ T_j_i @ invert_transform(poses[i])
    for q in members[a]:
        poses[q] = T_b_a @ poses[q]
        group[q] = b
    members[b] += members.pop(a)
    return b


def _weigh(x, proposal, state, support, *, surfaces, scenes, areas, tol, params, reg_params, centres, radii, cache,
           gap):
    """(ok, gain, priority) of merging the sub-assemblies of proposal ``x`` (i, j, T_j_i, score)."""
    group, poses, members = state
    i, j, T_j_i, score = proposal
    a, b = group[i], group[j]
    if len(members[a]) == 1 and len(members[b]) == 1:
        return True, score, score + support[x]  # the pair itself, scored by registration
    # the source's sub-assembly a moves into the frame of the target's, b
    T_b_a = poses[j] @ T_j_i @ invert_transform(poses[i])
    trial = {q: T_b_a @ poses[q] for q in members[a]}
    trial.update({p: poses[p] for p in members[b]})
    scores = _evaluate([(q, p) for q in members[a] for p in members[b]], trial, surfaces, scenes,
                       tol=tol, reg_params=reg_params, centres=centres, radii=radii, cache=cache, gap=gap)
    ok = all(pen <= params.max_penetration * min(areas[p], areas[q]) for (q, p), (_, _, pen) in scores.items())
    gain = sum(s for s, _, _ in scores.values())
    return ok, gain, gain


def group_surface(
    surfaces: list[FractureSurface], T_group_fragment: np.ndarray, *, tol: float, gap: float = 0.0
) -> FractureSurface:
    """One FractureSurface for a sub-assembly: its members' fracture surfaces that are still
    free (farther than ``2 tol + gap`` from another member's), in the group frame.

    The samples of the members are thinned to one common density (the coarsest member's),
    taking each member's first samples (they are in random order), so the result is
    deterministic.
    """
    m = len(surfaces)
    moved = [transform_points(T_group_fragment[k], s.samples) for k, s in enumerate(surfaces)]
    keys_moved = [transform_points(T_group_fragment[k], s.keypoints) for k, s in enumerate(surfaces)]
    # bounding balls of each member's samples and keypoints: only members whose balls come
    # within the reach can hold a point near another's (the same answer, a few trees a
    # member instead of one of the whole group)
    reach = 2 * tol + gap
    balls = [_ball(np.vstack([x, y])) for x, y in zip(moved, keys_moved)]
    centres, radii = np.array([c for c, _ in balls]).reshape(m, 3), np.array([r for _, r in balls])
    has_samples = np.array([len(x) > 0 for x in moved])
    free_samples, free_keys = [], []
    for k, s in enumerate(surfaces):
        near = (np.linalg.norm(centres - centres[k], axis=1) <= radii[k] + radii + reach) & has_samples
        near[k] = False
        others = [moved[o] for o in np.flatnonzero(near)]
        if others and len(moved[k]):
            tree = cKDTree(np.vstack(others))
            free_samples.append(~np.isfinite(tree.query(moved[k], distance_upper_bound=reach)[0]))
            keys = keys_moved[k]
            free_keys.append(~np.isfinite(tree.query(keys, distance_upper_bound=reach)[0]) if len(keys)
                             else np.zeros(0, bool))
        else:
            free_samples.append(np.ones(len(s.samples), bool))
            free_keys.append(np.ones(len(s.keypoints), bool))

    def thin(points, normals, keep, unit, flags=None):
        """Concatenate each member's kept points (their normals and flags, where given),
        thinned to one area per point (the largest)."""
        common = max(unit)
        out_p, out_n, out_f = [], [], []
        for k in range(m):
            idx = np.flatnonzero(keep[k])
            idx = idx[: int(round(len(idx) * unit[k] / common))] if common > 0 else idx[:0]
            out_p.append(transform_points(T_group_fragment[k], points[k][idx]))
            if normals is not None:
                out_n.append(normals[k][idx] @ T_group_fragment[k][:3, :3].T)
            if flags is not None:
                out_f.append(flags[k][idx])
        return (np.vstack(out_p), (np.vstack(out_n) if normals is not None else None), common,
                (np.concatenate(out_f) if flags is not None else None))

    samples, sample_normals, sample_area, _ = thin([s.samples for s in surfaces], [s.sample_normals for s in surfaces],
                                                   free_samples, [s.sample_area for s in surfaces])
    labelled = all(s.surface_normals is not None and s.surface_original is not None for s in surfaces)
    surface, surface_normals, surface_area, surface_original = thin(
        [s.surface for s in surfaces], [s.surface_normals for s in surfaces] if labelled else None,
        [np.ones(len(s.surface), bool) for s in surfaces], [s.surface_area for s in surfaces],
        [s.surface_original for s in surfaces] if labelled else None)
    R = [T[:3, :3] for T in T_group_fragment]
    return FractureSurface(
        keypoints=np.vstack([transform_points(T_group_fragment[k], s.keypoints[free_keys[k]])
                             for k, s in enumerate(surfaces)]),
        keypoint_normals=np.vstack([s.keypoint_normals[free_keys[k]] @ R[k].T for k, s in enumerate(surfaces)]),
        signature=np.vstack([s.signature[free_keys[k]] for k, s in enumerate(surfaces)]),
        samples=samples,
        sample_normals=sample_normals,
        sample_area=sample_area,
        surface=surface,
        surface_area=surface_area,
        fracture_area=float(sum(f.sum() * s.sample_area for f, s in zip(free_samples, surfaces))),
        area=float(sum(s.area for s in surfaces)),
        keypoint_tangents=None if any(s.keypoint_tangents is None for s in surfaces) else np.vstack(
            [s.keypoint_tangents[free_keys[k]] @ R[k].T for k, s in enumerate(surfaces)]),
        surface_normals=surface_normals,
        surface_original=surface_original,
    )


def assemble(
    surfaces: list[FractureSurface],
    meshes: list[tuple[np.ndarray, np.ndarray]],
    pair_results: dict,
    *,
    size: float,
    params: AssemblyParams = AssemblyParams(),
    reg_params: RegistrationParams = RegistrationParams(),
    seed: int = 0,
    jobs: int = 1,
    scheduler: str | None = None,
    memo: GroupMemo | None = None,
) -> Assembly:
    """Merge fragments into sub-assemblies from their pairwise candidates, then refine.

    When greedy merging stops, the sub-assemblies themselves are registered against each
    other (their free fracture surfaces, :func:`group_surface`): a piece that touches a
    sub-assembly in several small places, none enough alone, is found this way. Up to
    ``params.group_rounds`` such rounds.

    Parameters
    ----------
    surfaces : FractureSurface per fragment
    meshes : (vertices, faces) per fragment, closed, in its own coordinates
    pair_results : (source, target) index pair -> PairResult with ``T_target_source`` candidates
    size : reference size (mesh units)
    params : AssemblyParams
    reg_params : the RegistrationParams the candidates were scored with (tolerance, weights)
    seed : for the sub-assembly registrations
    jobs, scheduler : the sub-assembly registrations of a round run in ``jobs`` processes,
        or on the Dask cluster at ``scheduler`` (the result depends on neither)
    memo : GroupMemo of sub-assembly registrations made by earlier calls (with the same
        meshes, size and seed); used and added to. An assembly after more pairs were
        registered, or after a new segmentation that left some fragments' surfaces as they
        were, forms many of the same sub-assemblies again

    Returns
    -------
    Assembly
    """
    n = len(surfaces)
    tol, gap = reg_params.tolerance * size, reg_params.gap * size
    scenes = [make_scene(v, f) for v, f in meshes]
    centres, radii = _spheres(surfaces)
    areas = np.array([s.area for s in surfaces])
    group = np.arange(n)
    poses = np.tile(np.eye(4), (n, 1, 1))  # T_group_fragment
    members = {k: [k] for k in range(n)}
    state = (group, poses, members)
    proposals = []  # (source, target, T_target_source, score)
    for (i, j), res in sorted(pair_results.items()):
        for c in res.candidates[: params.candidates]:
            if c.score >= params.min_gain:
                proposals.append((i, j, c.T_target_source, c.score))
    cache: dict = {}
    # merges are ranked and verified on a thinned sample (4x fewer queries); final contacts use all
    quick = [_thinned(s, params.verify_samples) for s in surfaces]
    common = dict(surfaces=quick, scenes=scenes, areas=areas, tol=tol, reach=reg_params.ransac_tolerance * size,
                  params=params, reg_params=reg_params, centres=centres, radii=radii, cache=cache, gap=gap)
    merges = _merge_from_starts(proposals, state, starts=params.starts, common=common)
    merges += _register_groups(proposals, state, surfaces=surfaces, meshes=meshes, size=size, tol=tol, gap=gap,
                               params=params, reg_params=reg_params, seed=seed, common=common,
                               registered=set(pair_results), jobs=jobs, scheduler=scheduler,
                               memo=GroupMemo() if memo is None else memo)
    for g in members.values():
        if len(g) > 1:
            poses[g] = refine(poses[g], [surfaces[k] for k in g], tol=tol, normal_angle=reg_params.normal_angle,
                              iterations=params.refine_iterations, max_iterations=params.refine_max_iterations,
                              stop=params.refine_stop, anchor=int(np.argmax(areas[g])),
                              levels=params.refine_levels, n_points=params.refine_samples, gap=gap,
                              rim_reach=params.rim_reach, rim_weight=params.rim_weight)

    # contacts at the final poses, and the groups renumbered by area
    contacts = []
    touching = np.zeros(n)
    for g in members.values():
        pairs = sorted((min(p, q), max(p, q)) for x, p in enumerate(g) for q in g[x + 1:])
        for (p, q), (s, c, pen) in sorted(_evaluate(pairs, poses, surfaces, scenes, tol=tol, reg_params=reg_params,
                                                    centres=centres, radii=radii, cache={}, gap=gap).items()):
            if c > 0:
                contacts.append(Contact(p, q, float(s), float(c), float(pen)))
                touching[p] += c
                touching[q] += c
    order = sorted(members, key=lambda r: (-areas[members[r]].sum(), min(members[r])))
    renumber = {r: k for k, r in enumerate(order)}
    group = np.array([renumber[r] for r in group])
    for g in members.values():  # each group's frame: its largest fragment's
        ref = invert_transform(poses[g[int(np.argmax(areas[g]))]])
        poses[g] = ref[None] @ poses[g]
    placed = (group == 0) & (len(members[order[0]]) > 1)
    fracture = np.array([s.fracture_area for s in surfaces])
    confidence = np.where(fracture > 0, np.minimum(1.0, touching / np.maximum(fracture, 1e-300)), 0.0)
    return Assembly(poses, group, placed, confidence, contacts, merges)


def _register_groups(proposals, state, *, surfaces, meshes, size, tol, gap, params, reg_params, seed, common,
                     registered, jobs=1, scheduler=None, memo):
    """Rounds of registering whole sub-assemblies against each other, each followed by a
    merge (:func:`_merge`) of every proposal so far; returns the merges made.

    Two sub-assemblies are registered only when some pair of their members was
    (``registered``: (i, j) pairs): with every pair registered, as by default, that is any
    two; with candidate pairs only (:mod:`retrieval`), the sub-assemblies the retrieval
    links, so the rounds grow with the candidate pairs, not with the square of the groups.
    A round's registrations run in ``jobs`` processes (or on the Dask cluster of
    ``scheduler``); each has its own random stream (:func:`_group_stream`), so the result
    depends on neither, and one made before (``memo``, by members and poses) is the same.
    """

    group, poses, members = state
    merges = []
    tried = set()
    built: dict = {}  # a sub-assembly's surface and mesh, by its members and their poses

    def surface_and_mesh(g: list[int]):
        key = (tuple(g), poses[g].tobytes())
        if key not in built:
            built[key] = (group_surface([surfaces[k] for k in g], poses[g], tol=tol, gap=gap),
                          _union([meshes[k] for k in g], poses[g]))
        return built[key]

    for _ in range(params.group_rounds):
        keys = sorted(members, key=lambda r: min(members[r]))
        # the sub-assemblies a registered pair links, once per round (not member by member)
        linked = {(min(group[i], group[j]), max(group[i], group[j])) for i, j in registered if group[i] != group[j]}
        todo = []
        for x, ga in enumerate(keys):
            for gb in keys[x + 1:]:
                a, b = sorted(members[ga]), sorted(members[gb])
                if len(a) == 1 and len(b) == 1 or (tuple(a), tuple(b)) in tried:
                    continue
                if (min(ga, gb), max(ga, gb)) not in linked:
                    continue
                tried.add((tuple(a), tuple(b)))
                todo.append((a, b))
        found = {(tuple(a), tuple(b)): memo.get(a, b, poses, surfaces, reg_params) for a, b in todo}
        ask = [(a, b) for a, b in todo if found[(tuple(a), tuple(b))] is None]
        tasks = [(*surface_and_mesh(a), *surface_and_mesh(b), _group_stream(seed, a, b)) for a, b in ask]
        for (a, b), res in zip(ask, pool_map(_group_worker, tasks, jobs=jobs, scheduler=scheduler,
                                             initializer=_group_worker_init, initargs=(size, reg_params))):
            memo.put(a, b, poses, surfaces, reg_params, res)
            found[(tuple(a), tuple(b))] = res
        new = []
        for a, b in todo:
            for c in found[(tuple(a), tuple(b))].candidates[: params.candidates]:
                # any member pair carries the motion; the merge verifies all of them
                new.append((a[0], b[0], invert_transform(poses[b[0]]) @ c.T_target_source @ poses[a[0]], c.score))
        if not new:
            break
        proposals += new
        more = _merge(proposals, state, **common)
        merges += more
        if not more:
            break
    return merges


@dataclass
class GroupMemo:
    """Registrations of one sub-assembly against another, made by earlier assemblies of a
    run, for later ones to reuse.

    A registration depends on the two sub-assemblies' members, their poses, the members'
    fracture surfaces and the registration options (the meshes, size and seed are a run's
    own); the random stream is made from the members (:func:`_group_stream`). An entry is
    keyed by members, poses and options and checked against the members' surfaces, array by
    array, so a retry with new fracture labels reuses exactly the registrations of
    sub-assemblies whose members kept theirs.
    """

    entries: dict = field(default_factory=dict)  # key -> (member surfaces, PairResult)

    @staticmethod
    def _key(a: list[int], b: list[int], poses: np.ndarray, reg_params) -> tuple:
        return tuple(a), poses[a].tobytes(), tuple(b), poses[b].tobytes(), reg_params

    def get(self, a: list[int], b: list[int], poses: np.ndarray, surfaces: list, reg_params):
        hit = self.entries.get(self._key(a, b, poses, reg_params))
        if hit is None or not all(same_surface(x, surfaces[k]) for x, k in zip(hit[0], [*a, *b])):
            return None
        return hit[1]

    def put(self, a: list[int], b: list[int], poses: np.ndarray, surfaces: list, reg_params, result) -> None:
        self.entries[self._key(a, b, poses, reg_params)] = ([surfaces[k] for k in [*a, *b]], result)


def _group_stream(seed: int, a: list[int], b: list[int]) -> np.random.Generator:
    """The random stream of registering sub-assembly ``a`` against ``b``, made from their
    members alone (a key of three or more numbers: never a pair's, :func:`pairs.match_pairs`)."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(len(a), *a, *b))))


def _group_worker_init(size, reg_params) -> None:
    worker_state.clear()
    worker_state.update(size=size, params=reg_params)


def _group_worker(task):
    from .registration import register_pair

    source, source_mesh, target, target_mesh, rng = task
    return register_pair(source, target, source_scene=make_scene(*source_mesh), target_scene=make_scene(*target_mesh),
                         size=worker_state["size"], params=worker_state["params"], rng=rng)


def _union(meshes: list[tuple[np.ndarray, np.ndarray]], T_group_fragment: np.ndarray):
    """(vertices, faces) of several meshes placed in one frame."""
    vertices, faces, offset = [], [], 0
    for (v, f), T in zip(meshes, T_group_fragment):
        vertices.append(transform_points(T, v))
        faces.append(f + offset)
        offset += len(v)
    return np.vstack(vertices), np.vstack(faces)


def _accumulate(AtA: np.ndarray, Atb: np.ndarray, col: dict[int, int], p: int, q: int, P: np.ndarray,
                Q: np.ndarray, N: np.ndarray, weight=1.0) -> None:
    """Add the rows ``(P − Q)·N`` of p's points P against q's points Q along N (all (k, 3),
    common frame), each weighing ``weight`` (scalar or (k,)), to the normal equations, for
    whichever of p and q is free."""
    weight = np.broadcast_to(np.asarray(weight, float), (len(P),))
    r = np.einsum("ij,ij->i", P - Q, N)
    blocks = []
    if p in col:
        blocks.append((col[p], np.hstack([np.cross(P, N), N])))
    if q in col:
        blocks.append((col[q], -np.hstack([np.cross(Q, N), N])))
    for ca, Ja in blocks:
        Atb[ca:ca + 6] -= Ja.T @ (weight * r)
        for cb, Jb in blocks:
            AtA[ca:ca + 6, cb:cb + 6] += Ja.T @ (weight[:, None] * Jb)


def _normal_equations(pairs: list[tuple[int, int]], pts: list[np.ndarray], nrm: list[np.ndarray], trees: dict,
                      col: dict[int, int], *, distance: float, cos_tol: float, gap: float, rims=None,
                      rim_reach: float = 0.0, rim_weight: float = 0.1, tol: float = 0.0):
    """The point-to-plane normal equations of one step of :func:`refine`.

    Parameters
    ----------
    pairs : (p, q) fragment pairs: p's samples against q's surface
    pts, nrm : per fragment, (s, 3) samples and their unit normals in the common frame
    trees : cKDTree of each target q's samples moved out by ``gap`` along their normals
    col : first column of each free fragment's 6 unknowns (rotation vector, translation)
    distance : matches further apart are ignored
    cos_tol : matched normals must be opposed within this cosine
    gap : separation kept between mating surfaces
    rims : per fragment, its rim points, their directions (common frame) and a cKDTree of the
        points, or None: each
        touching pair's rim points also count, along the direction across the other's matched
        rim point (:func:`registration.rim_pairs` within ``rim_reach``, robust weights on the
        scale of ``tol``), with ``rim_weight`` times the weight of the pair's contact rows in all

    Returns
    -------
    AtA (6 f, 6 f), Atb (6 f,), the number of matched samples, the pairs that matched any
    """
    n = 6 * len(col)
    AtA = np.zeros((n, n))
    Atb = np.zeros(n)
    rows = 0
    touching = []
    for p, q in pairs:
        ok, j = opposed_neighbours(trees[q], pts[p], nrm[p], nrm[q], reach=distance, cos_tol=cos_tol)
        if not ok.any():
            continue
        touching.append((p, q))
        N = nrm[q][j[ok]]
        _accumulate(AtA, Atb, col, p, q, pts[p][ok], pts[q][j[ok]] + gap * N, N)
        rows += int(ok.sum())
        if rims is None or rims[p] is None or rims[q] is None:
            continue
        P, Q, V, w = rim_pairs(*rims[p][:2], *rims[q][:2], reach=rim_reach, tol=tol, tree=rims[q][2])
        if len(P) >= 6:
            _accumulate(AtA, Atb, col, p, q, P, Q, V, weight=rim_weight * float(ok.sum()) * w / w.sum())
    return AtA, Atb, rows, touching


def _largest_motion(x: np.ndarray, free: list[int], T: np.ndarray, centres: np.ndarray,
                    radii: np.ndarray) -> float:
    """The farthest any fragment's samples move by the step ``x`` (6 unknowns per fragment
    of ``free``, in order: rotation vector, translation) taken at poses ``T`` (before it): a
    bound from each one's bounding sphere (``centres`` in its own frame, ``radii``)."""
    step = x.reshape(len(free), 6)
    w, t = step[:, :3], step[:, 3:]
    centre = np.einsum("kij,kj->ki", T[free, :3, :3], centres[free]) + T[free, :3, 3]
    move = np.linalg.norm(np.cross(w, centre) + t, axis=1) + np.linalg.norm(w, axis=1) * radii[free]
    return float(move.max()) if len(move) else 0.0


def refine(
    T_group_fragment: np.ndarray,
    surfaces: list[FractureSurface],
    *,
    tol: float,
    normal_angle: float = 30.0,
    iterations: int = 15,
    max_iterations: int = 100,
    stop: float = 0.01,
    anchor: int = 0,
    levels: tuple[float, ...] = (2.0, 1.0),
    n_points: int = 1500,
    gap: float = 0.0,
    rim_reach: float = 0.0,
    rim_weight: float = 0.1,
) -> np.ndarray:
    """Joint point-to-plane refinement of the poses of one sub-assembly.

    Every pair of fragments contributes its fracture samples within a distance threshold
    (``levels`` times ``tol``, coarse to fine) of the other's, with opposed normals; all
    poses but the anchor's move at once (linearized rotations, damped least squares).
    With ``rim_reach`` > 0, at the finest threshold each touching pair's rims
    (:func:`features.rim_points`) within ``rim_reach`` times it of each other count too,
    across the rim: contact leaves a smooth break free to slide along its mate, the shared
    outline does not.

    Parameters
    ----------
    T_group_fragment : (m, 4, 4) poses in a common frame
    surfaces : FractureSurface per fragment
    tol : contact tolerance (mesh units)
    normal_angle : degrees from exactly opposed normals still counted
    iterations : per coarse level
    max_iterations, stop : the finest level iterates until no fragment's samples move more
        than ``stop * tol`` in an iteration, at most ``max_iterations`` times
    anchor : index of the fragment that stays fixed
    n_points : fracture samples per fragment used (the first: they are in random order)
    gap : separation kept between mating surfaces (mesh units; RegistrationParams.gap)
    rim_reach : at the finest level, rim points match within this multiple of its threshold
        (0: rims unused); rim_weight : their rows' weight in all, as a share of the contact
        rows' (light: they decide the motions contact leaves free, :func:`registration.icp`)

    Returns
    -------
    (m, 4, 4) refined poses (a new array)
    """
    T = np.array(T_group_fragment, dtype=float, copy=True)
    m = len(T)
    cos_tol = np.cos(np.radians(normal_angle))
    free = [k for k in range(m) if k != anchor]
    col = {k: 6 * x for x, k in enumerate(free)}
    centres, radii = _spheres(surfaces)
    for level, factor in enumerate(levels):
        distance, finest = factor * tol, level == len(levels) - 1
        pairs = [(p, q) for p in range(m) for q in range(m) if p != q and len(surfaces[p].samples)
                 and len(surfaces[q].samples) and _near(T[p], T[q], p, q, centres, radii, distance + gap)]
        for _ in range(max_iterations if finest else iterations):
            pts = [transform_points(T[k], s.samples[:n_points]) for k, s in enumerate(surfaces)]
            nrm = [s.sample_normals[:n_points] @ T[k][:3, :3].T for k, s in enumerate(surfaces)]
            # each source sample is matched to the target's surface moved out by the gap
            trees = {q: cKDTree(pts[q] + gap * nrm[q]) for q in {q for _, q in pairs}}
            rims = None
            if rim_reach > 0 and finest:  # once contact has settled
                rims = [None if s.rim is None or len(s.rim) < 6 else
                        (transform_points(T[k], s.rim), s.rim_directions @ T[k][:3, :3].T) for k, s in enumerate(surfaces)]
                rims = [r if r is None else (*r, cKDTree(r[0])) for r in rims]
            AtA, Atb, rows, touching = _normal_equations(pairs, pts, nrm, trees, col, distance=distance,
                                                         cos_tol=cos_tol, gap=gap, rims=rims,
                                                         rim_reach=rim_reach * distance, rim_weight=rim_weight,
                                                         tol=tol)
            if rows < 6:
                return T
            scale = max(np.trace(AtA) / max(len(AtA), 1), 1e-300)
            x = np.linalg.solve(AtA + 1e-6 * scale * np.eye(len(AtA)), Atb)
            converged = finest and _largest_motion(x, free, T, centres, radii) <= stop * tol
            for k, c in col.items():
                step = np.eye(4)
                step[:3, :3] = rotation_from_vector(x[c:c + 3])
                step[:3, 3] = x[c + 3:c + 6]
                T[k] = step @ T[k]
            pairs = touching  # the motions are small: pairs apart now stay apart in this level
            if converged or np.abs(x).max() < 1e-7 * max(tol, 1e-300):
                break
    return T




def contact_points(
    assembly: Assembly,
    surfaces: list[FractureSurface],
    meshes: list[tuple[np.ndarray, np.ndarray]],
    *,
    tol: float,
    normal_angle: float = 30.0,
    count: int = 40,
    gap: float = 0.0,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Where each contact of the assembly touches: point pairs for pictures and reports.

    Returns
    -------
    One (points_a, points_b) per ``assembly.contacts`` entry: up to ``count`` (k, 3) touching
    fracture samples of fragment ``a`` spread over the contact (a's coordinates) and the
    closest points of ``b`` to them (b's coordinates).
    """
    out = []
    scenes = {}
    for c in assembly.contacts:
        if c.b not in scenes:
            scenes[c.b] = make_scene(*meshes[c.b])
        T_b_a = invert_transform(assembly.T_group_fragment[c.b]) @ assembly.T_group_fragment[c.a]
        touching, closest = touching_samples(surfaces[c.a], surfaces[c.b], T_b_a, target_scene=scenes[c.b], tol=tol,
                                             normal_angle=normal_angle, gap=gap)
        points_a = surfaces[c.a].samples[touching]
        keep = farthest_points(points_a, count)
        out.append((points_a[keep], closest[keep]))
    return out


def contact_faces(
    assembly: Assembly,
    meshes: list[tuple[np.ndarray, np.ndarray]],
    *,
    tol: float,
    gap: float = 0.0,
    normal_angle: float = 60.0,
) -> list[np.ndarray]:
    """Which faces of each fragment touch another fragment of its sub-assembly.

    A face touches when its centre lies within ``tol`` of ``gap`` from the surface of a
    fragment it is in contact with (``assembly.contacts``), facing it: normals opposed
    within ``normal_angle`` degrees (mating surfaces face each other; the original surface
    beside a seam meets the other side's break at a right angle; the margin is for a
    scan's noisy face normals).

    Returns
    -------
    (f,) bool per fragment, over its faces
    """
    import open3d as o3d

    out = [np.zeros(len(f), bool) for _, f in meshes]
    scenes: dict = {}
    faces: dict = {}  # per fragment: its face centres and normals, in its own frame
    for c in assembly.contacts:
        for p, q in ((c.a, c.b), (c.b, c.a)):
            if q not in scenes:
                scenes[q] = make_scene(*meshes[q])
            if p not in faces:
                v, f = meshes[p]
                faces[p] = v[f].mean(axis=1), face_normals(v, f)
            T_q_p = invert_transform(assembly.T_group_fragment[q]) @ assembly.T_group_fragment[p]
            centres = transform_points(T_q_p, faces[p][0])
            closest = scenes[q].compute_closest_points(o3d.core.Tensor(centres.astype(np.float32)))
            dist = np.linalg.norm(closest["points"].numpy().astype(np.float64) - centres, axis=1)
            facing = (np.einsum("ij,ij->i", faces[p][1] @ T_q_p[:3, :3].T, closest["primitive_normals"].numpy())
                      < -np.cos(np.radians(normal_angle)))
            out[p] |= (np.abs(dist - gap) < tol) & facing
    return out


def world_poses(assembly: Assembly, surfaces: list[FractureSurface], *, gap: float) -> np.ndarray:
    """``T_world_fragment`` for every fragment: group 0 where it is (the world frame is its
    largest fragment's), every other sub-assembly and lone fragment moved beside it along
    +x, ``gap`` apart, so a picture or a viewer shows them apart and never overlapping.

    Returns
    -------
    (n, 4, 4)
    """
    T = np.array(assembly.T_group_fragment, dtype=float, copy=True)

    def box(members):
        pts = np.vstack([transform_points(T[k], surfaces[k].surface) for k in members])
        return pts.min(axis=0), pts.max(axis=0)

    lo, hi = box(np.flatnonzero(assembly.group == 0))
    x = hi[0] + gap
    for g in range(1, int(assembly.group.max()) + 1):
        members = np.flatnonzero(assembly.group == g)
        if len(members) == 0:
            continue
        glo, ghi = box(members)
        shift = np.eye(4)
        shift[:3, 3] = [x - glo[0], 0.5 * (lo[1] + hi[1] - glo[1] - ghi[1]), 0.5 * (lo[2] + hi[2] - glo[2] - ghi[2])]
        T[members] = shift[None] @ T[members]
        x += ghi[0] - glo[0] + gap
    return T


__all__ = [
    "Assembly", "AssemblyParams", "Contact", "assemble", "contact_points", "group_surface", "refine", "world_poses",
]
