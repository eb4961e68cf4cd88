"""Loop support of a merge: three fragments placed right close a loop of relative poses."""

from types import SimpleNamespace

import numpy as np

from reassemble.assembly import _cycle_support
from reassemble.geometry import invert_transform, make_transform


def _random_pose(rng) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return make_transform(q * np.sign(np.linalg.det(q)), rng.normal(size=3))


def test_a_true_placement_is_supported_by_the_loop_and_a_wrong_one_is_not():
    rng = np.random.default_rng(0)
    surfaces = [SimpleNamespace(surface=rng.normal(size=(50, 3))) for _ in range(3)]
    T_world = [_random_pose(rng) for _ in range(3)]

    def rel(i, j):  # the true T_j_i
        return invert_transform(T_world[j]) @ T_world[i]

    wrong = make_transform(np.eye(3), [0.5, 0, 0]) @ rel(1, 2)
    proposals = [(0, 1, rel(0, 1), 0.3), (0, 2, rel(0, 2), 0.2), (1, 2, wrong, 0.4), (1, 2, rel(1, 2), 0.25)]
    support = _cycle_support(proposals, surfaces, reach=0.05)
    # the true (1, 2) closes the loop 1 -> 0 -> 2; the wrong one, scored higher, closes none
    assert support[3] == 0.2 and support[2] == 0.0
    assert proposals[3][3] + support[3] > proposals[2][3] + support[2]
    # and the true (0, 1) is closed by 0 -> 2 -> 1 through the true (1, 2) only
    assert support[0] == 0.2 and support[1] == 0.25
    # a reach below the noise of the poses closes nothing
    noisy = [(i, j, make_transform(np.eye(3), [0.01, 0, 0]) @ T, s) for i, j, T, s in proposals]
    assert not _cycle_support(noisy, surfaces, reach=0.001).any()


def _support_one_by_one(proposals, surfaces, *, reach, points=32):
    """The loop support proposal by proposal, as first written: the reference of the grouped one."""
    from reassemble.geometry import transform_points

    rel = {}
    for i, j, T, s in proposals:
        rel.setdefault((i, j), []).append((T, s))
        rel.setdefault((j, i), []).append((invert_transform(T), s))
    stacked = {key: (np.array([T for T, _ in v]), np.array([s for _, s in v])) for key, v in rel.items()}
    others = {}
    for i, k in rel:
        others.setdefault(i, set()).add(k)
    support = np.zeros(len(proposals))
    for x, (i, j, T, _) in enumerate(proposals):
        pts = surfaces[i].surface[:points]
        target = transform_points(T, pts)
        for k in sorted(others.get(i, set()) & others.get(j, set()) - {i, j}):
            (A, sa), (B, sb) = stacked[(i, k)], stacked[(k, j)]
            C = np.einsum("bij,ajk->baik", B, A)
            moved = np.einsum("baij,pj->bapi", C[..., :3, :3], pts) + C[:, :, None, :3, 3]
            agree = np.linalg.norm(moved - target, axis=-1).max(axis=-1) <= reach
            if agree.any():
                support[x] += float(np.minimum.outer(sb, sa)[agree].max())
    return support


def test_loop_support_grouped_by_pair_equals_proposal_by_proposal():
    """Six fragments, several candidates per pair (true ones, slightly off ones, wrong ones):
    the support computed once per pair of fragments is the reference's, to the bit."""
    rng = np.random.default_rng(3)
    n = 6
    surfaces = [SimpleNamespace(surface=rng.normal(size=(40, 3))) for _ in range(n)]
    T_world = [_random_pose(rng) for _ in range(n)]
    proposals = []
    for i in range(n):
        for j in range(n):
            if i == j or rng.random() < 0.3:
                continue
            true = invert_transform(T_world[j]) @ T_world[i]
            for _ in range(int(rng.integers(1, 4))):
                kind = rng.random()
                T = true if kind < 0.4 else (make_transform(np.eye(3), rng.normal(0, 0.01, 3)) @ true
                                               if kind < 0.7 else _random_pose(rng))
                proposals.append((i, j, T, float(rng.uniform(0.05, 0.5))))
    got = _cycle_support(proposals, surfaces, reach=0.05)
    assert np.array_equal(got, _support_one_by_one(proposals, surfaces, reach=0.05))
    assert (got > 0).sum() > 10
