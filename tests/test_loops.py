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
