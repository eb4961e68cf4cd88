"""benchmarks.accuracy.field through `reassemble bench`: the segmentation F1 of bench's extra
hook and the rows made of bench's records (the solving itself is tested in test_bench)."""

import numpy as np
import pytest

from benchmarks.accuracy.field import row, segmentation_f1, segmentation_scores
from reassemble.bench import BenchSet
from reassemble.files import MeshData
from reassemble.puzzle import PuzzleFiles


def _square(z):
    """Two triangles of area 1/2 each, and a third of area 9/2: faces of known areas (and centres)."""
    v = np.array([[0, 0, z], [1, 0, z], [0, 1, z], [1, 1, z], [3, 0, z], [0, 3, z]], float)
    return v, np.array([[0, 1, 2], [1, 3, 2], [0, 4, 5]])


def _puzzle():
    meshes, labels = {}, {}
    for k, name in enumerate(("fragment_00", "fragment_01")):
        v, f = _square(k)
        meshes[name] = MeshData(vertices=v, faces=f, path=None)
        labels[name] = np.array([1, 0, 1], np.int8)  # the exact labels: faces 0 and 2 are fracture
    return PuzzleFiles(root=None, ground_truth={}, meshes=meshes, labels=labels)


def test_segmentation_f1_is_area_weighted():
    puzzle = _puzzle()
    meshes = {n: (m.vertices, m.faces) for n, m in puzzle.meshes.items()}
    exact = {n: puzzle.labels[n] == 1 for n in meshes}
    assert segmentation_f1(meshes, exact, puzzle) == {"precision": 1.0, "recall": 1.0, "f1": 1.0}
    # fragment_00: the small fracture face missed, the small intact one taken: area 0.5 of 10 each way
    guess = dict(exact, fragment_00=np.array([False, True, True]))
    s = segmentation_f1(meshes, guess, puzzle)
    assert s["precision"] == pytest.approx(0.95) and s["recall"] == pytest.approx(0.95)
    assert s["f1"] == pytest.approx(0.95)
    # a fragment split in bodies ('stem.1') with its faces reordered: labels carried by nearest face centre
    v, f = meshes["fragment_01"]
    split = {"fragment_00": meshes["fragment_00"], "fragment_01.1": (v, f[::-1])}
    labels = {"fragment_00": exact["fragment_00"], "fragment_01.1": exact["fragment_01"][::-1]}
    assert segmentation_f1(split, labels, puzzle)["f1"] == 1.0
    with pytest.raises(ValueError, match="no fracture labels"):
        segmentation_f1(meshes, {}, puzzle)


def test_segmentation_scores_reads_the_puzzles_labels(tmp_path, monkeypatch):
    import benchmarks.accuracy.field as field

    puzzle = _puzzle()
    monkeypatch.setattr("reassemble.puzzle.read_puzzle", lambda path: puzzle if path.parent == tmp_path else None)
    meshes = {n: (m.vertices, m.faces) for n, m in puzzle.meshes.items()}
    predicted = {n: {"transform": np.eye(4), "placed": True, "fracture": puzzle.labels[n] == 0} for n in meshes}
    s = field.segmentation_scores(bench_set=BenchSet("p", str(tmp_path), "puzzle", 2, None), meshes=meshes,
                                  predicted=predicted)
    assert s["f1"] == 0.0 and segmentation_scores is field.segmentation_scores


def test_rows_from_bench_records():
    ok = {"set": "p", "error": None, "pieces": 3, "placed": 3, "time_s": 9.0,
          "timings_s": {"load": 0.5, "solve": 7.5, "score": 1.0}, "solver": {"cpu_s": 7.0},
          "metrics": {"anchor_largest": {"part_acc_strict": 2 / 3, "solved": False, "rot_geodesic_rmse_deg": 4.0}},
          "extra": {"precision": 0.8, "recall": 0.9, "f1": 0.85}}
    r = row(ok)
    assert r == {"name": "p", "time": 8.0, "cpu": 7.0, "fragments": 3, "placed": 3, "part_acc_strict": 2 / 3,
                 "solved": False, "rot_rmse_deg": 4.0, "precision": 0.8, "recall": 0.9, "f1": 0.85}
    bad = row({"set": "q", "error": "timeout (60 s)", "pieces": 4, "time_s": 60.2})
    assert bad["error"] == "timeout (60 s)" and bad["solved"] is False and bad["f1"] == 0.0 and bad["time"] == 60.2
    lost = row({"set": "q", "error": "KilledWorker: ...", "pieces": 4, "time_s": None, "lost": True})
    assert lost["time"] == 0.0 and lost["part_acc_strict"] == 0.0
