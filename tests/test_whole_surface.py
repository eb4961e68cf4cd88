"""A fragment whose break the segmentation missed is matched by its whole surface."""

import json

import numpy as np
import pytest

from reassemble import prepare
from reassemble.pipeline import evaluate_files, run_to_folder
from reassemble.segmentation import Segmentation, all_fracture

from .conftest import SMALL_COW


def test_all_fracture_keeps_what_the_evidence_found_original():
    seg = Segmentation(np.array([True, False, False]), np.array([0.9, 0.1, 0.2]), np.zeros(3, int),
                       np.array([0, -1, -1]), 1.0, 3.0)
    whole = all_fracture(seg)
    assert whole.fracture.all() and whole.fracture_area == whole.area == 3.0
    assert (whole.region == 0).all()
    assert whole.original.tolist() == [False, True, True]
    assert all_fracture(whole).original.tolist() == [False, True, True]  # not overwritten by the first override
    assert seg.original is None and seg.fracture.tolist() == [True, False, False]  # input unchanged


@pytest.mark.slow
def test_a_fragment_labelled_original_all_over_is_placed_by_its_whole_surface(puzzles, tmp_path, monkeypatch):
    """Every segmentation (the first and each retry) finds no break on fragment_01: before
    the whole-surface retry it stayed unplaced; its mate's side of the break was found."""
    segment = prepare.segment

    def blind(meshes, descriptors, **kw):
        segs = segment(meshes, descriptors, **kw)
        s = segs[1]
        none = np.zeros(len(s.fracture), bool)
        segs[1] = Segmentation(none, s.probability, s.patch, np.full(len(none), -1), 0.0, s.area)
        return segs

    monkeypatch.setattr(prepare, "segment", blind)
    puzzle = puzzles.puzzle(*SMALL_COW)
    out = tmp_path / "run"
    run_to_folder([puzzle / "fragments"], out, seed=0)
    report = json.loads((out / "report.json").read_text())
    assert report["summary"]["fallback"]["method"].endswith("+whole:fragment_01")
    assert json.loads((out / "config.json").read_text())["segment"]["whole"] == ["fragment_01"]
    scores = evaluate_files(out / "transforms.json", puzzle / "ground_truth.json")
    assert scores["alignments"]["anchor_largest"]["summary"]["solved"]
