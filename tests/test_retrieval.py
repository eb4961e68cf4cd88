"""Candidate pairs of large sets: partner votes, the pairs registered first and asked for later."""

from types import SimpleNamespace

import numpy as np
import pytest

from reassemble.config import Config, with_setting
from reassemble.errors import ReassembleError
from reassemble.features import mate_signature
from reassemble.geometry import invert_transform, rotation_angle_deg
from reassemble.pipeline import match_pairs, reassemble
from reassemble.retrieval import first_pairs, more_pairs, partner_votes, ranked_partners


def _mated_signatures(rng, pairs_of_mates: int, keypoints: int = 60, dims: int = 6):
    """Signatures of 2 x ``pairs_of_mates`` fragments: fragment 2k+1's keypoints carry the mate
    signatures of fragment 2k's (a little noise), every pair of mates unlike the others."""
    surfaces = []
    for _ in range(pairs_of_mates):
        sig = rng.normal(size=(keypoints, dims)) * 3.0
        mate = mate_signature(sig) + rng.normal(scale=0.05, size=sig.shape)
        surfaces += [SimpleNamespace(signature=sig), SimpleNamespace(signature=mate[rng.permutation(keypoints)])]
    return surfaces


def test_votes_find_the_mates():
    rng = np.random.default_rng(0)
    surfaces = _mated_signatures(rng, 4)
    V = partner_votes(surfaces, neighbours=4)
    assert V.shape == (8, 8) and np.allclose(V, V.T) and np.all(np.diag(V) == 0)
    mates = np.arange(8) ^ 1  # 0 <-> 1, 2 <-> 3, ...
    assert np.array_equal(ranked_partners(V)[:, 0], mates)
    assert first_pairs(V, partners=1) == [(0, 1), (2, 3), (4, 5), (6, 7)]
    # a fragment with no fracture keypoints gets no votes and votes for none
    V2 = partner_votes(surfaces + [SimpleNamespace(signature=np.zeros((0, 6)))], neighbours=4)
    assert np.all(V2[8] == 0) and np.allclose(V2[:8, :8], V)


def test_more_pairs_skip_the_registered_ones():
    V = np.array([[0, 5, 3, 1, 2],
                  [5, 0, 1, 1, 1],
                  [3, 1, 0, 4, 0],
                  [1, 1, 4, 0, 0],
                  [2, 1, 0, 0, 0]], float)
    registered = set(first_pairs(V, partners=1))
    assert registered == {(0, 1), (2, 3), (0, 4)}
    # fragment 0's next partners after 1: 2 (3 votes), then 4 (registered), then 3
    assert more_pairs(V, [0], registered, count=1) == [(0, 2)]
    assert more_pairs(V, [0], registered, count=2) == [(0, 2), (0, 3)]
    # two fragments asking for the same pair: it is registered once, and the second asker
    # gets its next partner instead; an exhausted fragment gets none
    assert more_pairs(V, [0, 2], registered, count=1) == [(0, 2), (1, 2)]
    everything = {(i, j) for i in range(5) for j in range(i + 1, 5)}
    assert more_pairs(V, [0, 1, 2], everything, count=3) == []


def test_retrieval_options_checked():
    with pytest.raises(ReassembleError, match="retrieval.partners"):
        with_setting(Config(), "retrieval.partners=0").check()


@pytest.mark.slow
def test_a_pair_registers_alike_alone_or_among_others(prepared):
    # each pair's random stream is its place among all pairs, whichever pairs are registered:
    # registering candidate pairs only gives each the result it has in a full run
    frags, size = prepared
    alone = match_pairs(frags, size=size, pairs=[(1, 2)], seed=3)[(1, 2)]
    among = match_pairs(frags, size=size, pairs=[(0, 1), (0, 3), (1, 2)], seed=3)[(1, 2)]
    assert len(alone.candidates) == len(among.candidates) > 0
    for x, y in zip(alone.candidates, among.candidates):
        assert np.array_equal(x.T_target_source, y.T_target_source) and x.score == y.score


@pytest.mark.slow
def test_candidate_pairs_and_asking_for_more_place_every_fragment(puzzle):
    # the 4-piece cow with retrieval forced on and one partner each: fewer pairs than all
    # are registered first; a fragment left unplaced asks for more, until all are placed
    meshes = {n: (m.vertices, m.faces) for n, m in puzzle.meshes.items()}
    config = Config()
    for setting in ("retrieval.min_fragments=2", "retrieval.partners=1", "retrieval.more=1"):
        config = with_setting(config, setting)
    result = reassemble(meshes, config, jobs=1)
    assert result.votes is not None and result.votes.shape == (4, 4)
    first = first_pairs(result.votes, partners=1)
    assert len(first) < 6 and set(first) <= set(result.pairs)
    assert result.assembly.placed.all()
    # and placed right: every fragment's pose relative to the first as in the truth
    truth = [np.array(puzzle.ground_truth["fragments"][f.name]["transform"]) for f in result.fragments]
    for k in range(1, len(truth)):
        rel = invert_transform(result.T_world[0]) @ result.T_world[k]
        true_rel = invert_transform(truth[0]) @ truth[k]
        assert rotation_angle_deg(rel[:3, :3], true_rel[:3, :3]) < 2.0
        assert np.linalg.norm(rel[:3, 3] - true_rel[:3, 3]) < 0.01 * result.size


def test_a_candidate_set_starts_with_planar_mates_and_tries_without():
    from reassemble.pipeline import _segmentations

    config = with_setting(Config(), "retrieval.min_fragments=16")
    first, retries = _segmentations(config, 15)  # every pair registered: mates only on a retry
    assert first is config and [r.segment.mates for r in retries][0] is True
    first, retries = _segmentations(config, 16)  # candidate pairs only: mates first
    assert first.segment.mates is True and retries[0].segment.mates is False
    assert [r.segment.method for r in retries] == [config.segment.method, config.segment.fallback]
    assert first.retrieval == config.retrieval and first.segment.method == config.segment.method
    for mates in ("true", "false"):  # a set choice: no retry on mates, whatever the size
        fixed = with_setting(config, f"segment.mates={mates}")
        for n in (4, 40):
            first, retries = _segmentations(fixed, n)
            assert first is fixed and [r.segment.method for r in retries] == [config.segment.fallback]


def test_large_sets_register_candidate_pairs_by_default():
    from reassemble.retrieval import candidates_only

    assert not candidates_only(Config().retrieval, 29) and candidates_only(Config().retrieval, 30)
    assert not candidates_only(with_setting(Config(), "retrieval.min_fragments=none").retrieval, 1000)
