"""The learned segmentation: the shipped model, its export from scikit-learn, and a cell
fracture (planar breaks, the case the roughness mixture inverts) segmented by it."""

import numpy as np
import pytest

from reassemble import segmenter
from reassemble.config import Config
from reassemble.errors import ReassembleError
from reassemble.geometry import face_areas
from reassemble.pipeline import break_to_folder, read_puzzle
from reassemble.prepare import describe_fragments
from reassemble.segmentation import SegmentParams, segment
from reassemble.synth import BreakParams


def test_the_shipped_model_loads_over_these_features():
    model = segmenter.shipped()
    assert model.meta["features"] == list(segmenter.FEATURE_NAMES)
    assert model.meta["format"] == segmenter.MODEL_FORMAT
    assert "train_segmenter" in model.meta["command"] and model.meta["trained_on"]
    # trained on the tuning half only: no validation mesh in its puzzles
    from data_synth.sets import FIELD_MESHES

    assert {FIELD_MESHES[n.split("_0")[0]].half for n in model.meta["trained_on"]} == {"tuning"}
    assert len(model.roots) > 10 and (model.left < len(model.feature)).all()


def test_predictions_are_deterministic_probabilities():
    model = segmenter.shipped()
    X = np.random.default_rng(0).normal(size=(200, len(segmenter.FEATURE_NAMES)))
    p = model.probability(X)
    assert ((p > 0) & (p < 1)).all() and p.std() > 0
    np.testing.assert_array_equal(p, model.probability(X.copy()))


def test_the_export_matches_scikit_learn(tmp_path):
    from sklearn.ensemble import HistGradientBoostingClassifier

    rng = np.random.default_rng(1)
    X = rng.normal(size=(400, 5))
    y = (X[:, 0] + 0.5 * X[:, 1] ** 2 + 0.3 * rng.normal(size=400) > 0.4).astype(int)
    w = rng.uniform(0.5, 2.0, size=400)
    gb = HistGradientBoostingClassifier(max_iter=30, max_leaf_nodes=7, early_stopping=False,
                                        random_state=0).fit(X, y, sample_weight=w)
    meta = {"format": segmenter.MODEL_FORMAT, "features": list(segmenter.FEATURE_NAMES)}
    ensemble = segmenter.from_sklearn(gb, meta)
    Xt = rng.normal(size=(300, 5))
    np.testing.assert_allclose(ensemble.probability(Xt), gb.predict_proba(Xt)[:, 1], rtol=0, atol=1e-12)
    segmenter.save(ensemble, tmp_path / "m.npz")
    again = segmenter.load(tmp_path / "m.npz")
    np.testing.assert_array_equal(again.probability(Xt), ensemble.probability(Xt))


def test_a_model_over_other_features_is_refused(tmp_path):
    model = segmenter.shipped()
    other = segmenter.TreeEnsemble(model.feature, model.threshold, model.left, model.right, model.value,
                                   model.roots, model.init, dict(model.meta, features=["a", "b"]))
    segmenter.save(other, tmp_path / "m.npz")
    with pytest.raises(ValueError, match="features"):
        segmenter.load(tmp_path / "m.npz")


def test_an_unknown_method_is_an_error():
    with pytest.raises(ReassembleError, match="segment.method"):
        SegmentParams(method="magic")


@pytest.fixture(scope="module")
def cells(tmp_path_factory):
    """A 3-piece cell fracture of the low-resolution cow: near-planar breaks at sharp edges."""
    out = tmp_path_factory.mktemp("cells") / "cow"
    break_to_folder("spot_low_resolution", out, params=BreakParams(pieces=3, style="cells"), seed=4)
    puzzle = read_puzzle(out / "ground_truth.json")
    names = sorted(puzzle.meshes)
    meshes = {n: (puzzle.meshes[n].vertices, puzzle.meshes[n].faces) for n in names}
    return describe_fragments(meshes, config=Config()), [puzzle.labels[n] == 1 for n in names]


def _f1(ds, truth, method):
    segs = segment([(v, f) for v, (_, f) in zip(ds.matched, ds.meshes)], ds.descriptors, size=ds.size,
                   params=SegmentParams(method=method), seed=0)
    area = np.concatenate([face_areas(*m) for m in ds.meshes])
    t = np.concatenate(truth)
    p = np.concatenate([s.fracture for s in segs])
    tp = area[t & p].sum()
    return 2 * tp / (area[t].sum() + area[p].sum())


@pytest.mark.slow  # ~20 s: the descriptors of three fragments
def test_cell_breaks_are_found(cells):
    ds, truth = cells
    assert _f1(ds, truth, "learned") > 0.85
