"""Candidate pairs: which fragments of a large set are registered, and in which order.

Registering every pair costs n (n - 1) / 2 registrations, about a second each: six hours
for 300 fragments. Here one k-d tree holds the fracture keypoints' signatures of the whole
set; each keypoint's mate signature (:func:`features.mate_signature`) votes for the
fragments owning its nearest signatures, and each fragment's best ``partners`` by votes
are registered first. A fragment the assembly leaves unplaced asks for its next ``more``
partners (:func:`more_pairs`), until it is placed or every pair it is in is registered.

Notes
-----
Votes do not need to find every touching pair: the assembly needs a connected set of true
contacts, and every other contact between placed fragments is found from the placement
(loop verification and refinement in :mod:`assembly` use the surfaces, not the pairs).
Measured on 50 Voronoi cells of one mesh, votes keep about half of the touching pairs among
each fragment's best six (``benchmarks/studies/retrieval_cues.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .features import FractureSurface, mate_signature


@dataclass(frozen=True)
class RetrievalParams:
    """Options of the candidate pairs.

    Parameters
    ----------
    min_fragments : sets with at least this many fragments register candidate pairs only;
        None: every set registers every pair. From 30 fragments every pair would take
        7 minutes and more on 2 cores (435 pairs, growing as n^2), where candidate pairs
        solved every large set measured: 20 Voronoi cells of spot, bunny and a torus
        (fractal cuts), 50 of spot (``python -m benchmarks.speed.scale``); the field
        benchmarks' sets (2-20 pieces) register every pair
    partners : each fragment's best partners by votes registered first (a pair is
        registered when either fragment has the other among them)
    more : further partners per round for a fragment the assembly leaves unplaced
    max_partners : a fragment asks for more only while registered against fewer partners
        than this, in each segmentation a run tries; the one it keeps asks on, until every
        fragment is placed or registered against every other (:func:`pipeline.reassemble`)
    neighbours : signatures of other fragments each keypoint votes for
    confidence : a placed fragment with less of its break in contact than this
        (:attr:`assembly.Assembly.confidence`) asks for more partners too, up to
        ``max_partners``: in a whole object every break has its mate, so a placed fragment
        with most of its break open is missing neighbours, or sits where it does not belong
    """

    min_fragments: int | None = 30
    partners: int = 4
    more: int = 4
    max_partners: int = 8
    neighbours: int = 8
    confidence: float = 0.5


def partner_votes(surfaces: list[FractureSurface], *, neighbours: int = 8) -> np.ndarray:
    """(n, n) symmetric votes: how much more often than chance each fragment's fracture
    keypoints find their mate signature among the other fragment's keypoints.

    Each keypoint's mate signature queries its ``neighbours`` nearest keypoints of other
    fragments in one k-d tree over the set; fragment i's votes for j are divided by those
    expected by chance (i's keypoints x ``neighbours`` x j's share of all keypoints), and
    both directions are added.
    """
    from scipy.spatial import cKDTree

    n = len(surfaces)
    sig = [s.signature for s in surfaces]
    V = np.zeros((n, n))
    if n < 2 or not any(len(x) for x in sig):
        return V
    owner = np.concatenate([np.full(len(x), i) for i, x in enumerate(sig)])
    counts = np.bincount(owner, minlength=n)
    tree = cKDTree(np.vstack([x for x in sig if len(x)]))
    for i, x in enumerate(sig):
        if not len(x):
            continue
        query = mate_signature(x)
        # a few more than ``neighbours``; the rows that found too few of other fragments
        # (most near i's own keypoints) again with enough to pass all of i's own
        k = min(2 * neighbours, len(owner))
        _, idx = tree.query(query, k=k)
        found = owner[idx.reshape(len(x), -1)]
        short = np.count_nonzero(found != i, axis=1) < neighbours
        if short.any() and k < len(owner):
            _, more = tree.query(query[short], k=min(neighbours + int(counts[i]), len(owner)))
            votes = [found[~short], owner[more.reshape(int(short.sum()), -1)]]
        else:
            votes = [found]
        for rows in votes:  # each row's first ``neighbours`` of other fragments
            other = rows != i
            first = other & (np.cumsum(other, axis=1) <= neighbours)
            V[i] += np.bincount(rows[first], minlength=n)
        V[i] /= np.maximum(len(x) * neighbours * counts / len(owner), 1e-300)
    np.fill_diagonal(V, 0.0)
    return V + V.T


def ranked_partners(votes: np.ndarray) -> np.ndarray:
    """(n, n - 1) every fragment's partners, most votes first (ties in index order)."""
    n = len(votes)
    order = np.argsort(-np.where(np.eye(n, dtype=bool), -np.inf, votes), axis=1, kind="stable")
    return order[:, : n - 1]


def first_pairs(votes: np.ndarray, *, partners: int) -> list[tuple[int, int]]:
    """The (i, j), i < j, registered first: j among i's best ``partners`` or i among j's."""
    order = ranked_partners(votes)
    keep = {(min(i, int(j)), max(i, int(j))) for i in range(len(order)) for j in order[i, :partners]}
    return sorted(keep)


def candidates_only(params: RetrievalParams, n: int) -> bool:
    """Whether a set of ``n`` fragments registers candidate pairs only (``params.min_fragments``)."""
    return params.min_fragments is not None and n >= params.min_fragments


def more_pairs(votes: np.ndarray, fragments, registered, *, count: int,
               limit: int | None = None) -> list[tuple[int, int]]:
    """For each of ``fragments``, its next ``count`` partners by votes whose pair is not in
    ``registered`` (a set of (i, j), i < j): the new (i, j), i < j, sorted. With ``limit``,
    a fragment already registered against that many partners asks for none."""
    order = ranked_partners(votes)
    partners = np.bincount(np.array(sorted(registered), int).reshape(-1), minlength=len(votes))
    new: set = set()
    for i in fragments:
        if limit is not None and partners[i] >= limit:
            continue
        added = 0
        for j in order[i]:
            key = (min(int(i), int(j)), max(int(i), int(j)))
            if key in registered or key in new:
                continue
            new.add(key)
            added += 1
            if added == count:
                break
    return sorted(new)


__all__ = ["RetrievalParams", "candidates_only", "first_pairs", "more_pairs", "partner_votes", "ranked_partners"]
