"""The graph cut tidies the fracture evidence; it never erases a face of the break."""

import numpy as np

from reassemble import segmentation as seg


def _chain(prob_by_patch: np.ndarray, *, edge: float) -> seg._Fragment:
    """Patches in a chain (one face each, unit area), smooth boundaries of length ``edge``."""
    k = len(prob_by_patch)
    pairs = np.column_stack([np.arange(k - 1), np.arange(1, k)])
    return seg._Fragment(
        patch=np.arange(k), pairs=pairs, dihedral=np.zeros(k - 1), edge_length=np.full(k - 1, edge),
        face_area=np.ones(k), patch_area=np.ones(k), log_residual=np.zeros(k), face_features=np.zeros((k, 2)),
    )


def test_a_break_face_with_a_smooth_rim_is_kept():
    # one large break face (30 patches), original surface (20), a second, smaller break
    # face (8) met at a shallow angle: cutting it out is cheaper than its area at full
    # weight, and moves under half the evidence, so only the per-face rule keeps it
    prob = np.r_[np.full(30, 0.995), np.full(20, 0.005), np.full(8, 0.995)]
    f = _chain(prob, edge=6.0)
    params = seg.SegmentParams()
    cut = seg._graph_cut(f, prob, params, weight=params.smoothness)
    assert not cut[50:].any(), "the case is not a knife edge: the plain cut keeps the small face"
    label = seg._tidy(f, prob, params)
    np.testing.assert_array_equal(label, prob > 0.5)


def test_specks_of_evidence_are_still_tidied():
    # a speck (1 patch) inside original surface is far smaller than the break face: removed
    prob = np.r_[np.full(30, 0.995), np.full(10, 0.005), [0.9], np.full(10, 0.005)]
    f = _chain(prob, edge=6.0)
    label = seg._tidy(f, prob, seg.SegmentParams())
    assert label[:30].all() and not label[30:].any()
