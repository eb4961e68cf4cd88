"""Open scans: holes found, filled so the surface bounds a solid, refused without --fill-holes."""

import hashlib

import numpy as np
import pytest
import trimesh

from data_synth.scans import punch_holes
from reassemble.errors import ReassembleError
from reassemble.holes import boundary_loops, fill_holes
from reassemble.files import load_mesh, write_ply
from reassemble.pipeline import Config, evaluate_files, read_puzzle, run_to_folder

from .conftest import SMALL_COW


def _capped_sphere(height: float):
    s = trimesh.creation.icosphere(subdivisions=3)
    keep = s.triangles_center[:, 2] < height
    return s, np.asarray(s.vertices), np.asarray(s.faces[keep])


def test_a_cut_sphere_is_closed_and_inputs_kept():
    sphere, v, f = _capped_sphere(0.8)
    v0, f0 = v.copy(), f.copy()
    assert len(boundary_loops(f)) == 1
    v2, f2, sizes = fill_holes(v, f, max_size=0.9)
    np.testing.assert_array_equal(v, v0)
    np.testing.assert_array_equal(f, f0)
    closed = trimesh.Trimesh(v2, f2, process=False)
    assert closed.is_watertight and closed.is_winding_consistent
    assert closed.volume > 0
    # the patch is flat: the lost cap's volume is all that is missing
    assert 0.95 * sphere.volume < closed.volume < sphere.volume
    assert len(sizes) == 1 and 0.4 < sizes[0] < 0.6


def test_a_non_convex_hole_and_the_size_limit():
    # an L-shaped hole of whole grid cells (no pinched corner) in the top of a box
    box = trimesh.creation.box(extents=(1.0, 1.0, 0.3))
    grid = box.subdivide().subdivide().subdivide()  # 8 x 8 cells of two triangles on each side
    c = grid.triangles_center
    i, j = (np.floor((c[:, :2] + 0.5) / 0.125).astype(int)).T
    ell = (c[:, 2] > 0.14) & (((j == 2) & (i >= 2) & (i <= 5)) | ((i == 5) & (j >= 2) & (j <= 5)))
    v, f = np.asarray(grid.vertices), np.asarray(grid.faces[~ell])
    assert len(boundary_loops(f)) == 1
    v2, f2, sizes = fill_holes(v, f, max_size=0.9)
    closed = trimesh.Trimesh(v2, f2, process=False)
    assert closed.is_watertight and closed.is_winding_consistent
    assert closed.volume == pytest.approx(box.volume, rel=1e-6)  # ear clipping: flat, no fan point
    assert len(v2) == len(v)
    v3, f3, sizes3 = fill_holes(v, f, max_size=0.1 * sizes[0])
    assert len(f3) == len(f) and sizes3 == sizes  # too large: left open, its size reported


def test_a_hole_touching_itself_is_split_at_the_pinch():
    grid = trimesh.creation.box(extents=(1.0, 1.0, 0.3)).subdivide().subdivide().subdivide()
    c = grid.triangles_center
    i, j = (np.floor((c[:, :2] + 0.5) / 0.125).astype(int)).T
    # two cells of the top meeting at one corner only
    pinch = (c[:, 2] > 0.14) & (((i == 2) & (j == 2)) | ((i == 3) & (j == 3)))
    f = np.asarray(grid.faces[~pinch])
    loops = boundary_loops(f)
    assert sorted(len(loop) for loop in loops) == [4, 4]
    v2, f2, _ = fill_holes(np.asarray(grid.vertices), f, max_size=0.9)
    closed = trimesh.Trimesh(v2, f2, process=False)
    assert closed.is_watertight and closed.volume == pytest.approx(0.3, rel=1e-6)


def test_the_loader_reads_an_open_scan_or_closes_it(tmp_path):
    _, v, f = _capped_sphere(0.8)
    path = tmp_path / "scan.ply"
    write_ply(path, v, f)
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    assert "1 hole(s) left open" in load_mesh(path).repairs  # its winding number bridges the hole
    with pytest.raises(ReassembleError, match="hole spanning"):
        load_mesh(path, fill_holes=0.1)
    m = load_mesh(path, fill_holes=0.75)
    assert len(m.filled_holes) == 1
    assert trimesh.Trimesh(m.vertices, m.faces, process=False).is_watertight
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before


@pytest.mark.slow
def test_open_scanned_fragments_are_reassembled(puzzles, tmp_path):
    """Each fragment of the 2-piece cow loses a patch of its original surface (an open scan)."""
    puzzle_dir = puzzles.puzzle(*SMALL_COW)
    puzzle = read_puzzle(puzzle_dir / "ground_truth.json")
    scans = tmp_path / "scans"
    punch_holes(puzzle_dir, scans, radius=0.03, seed=3)
    report = run_to_folder([scans], tmp_path / "open", seed=0)  # no --fill-holes: read open
    assert sum("1 hole(s) left open" in w for w in report["warnings"]) == len(puzzle.meshes), report["warnings"]
    scores = evaluate_files(tmp_path / "open" / "transforms.json", puzzle_dir / "ground_truth.json")
    assert scores["alignments"]["anchor_largest"]["summary"]["solved"]
    report = run_to_folder([scans], tmp_path / "out", seed=0, config=Config(fill_holes=0.25))
    assert sum("closed 1 hole(s)" in w for w in report["warnings"]) == len(puzzle.meshes)
    scores = evaluate_files(tmp_path / "out" / "transforms.json", puzzle_dir / "ground_truth.json")
    assert scores["alignments"]["anchor_largest"]["summary"]["solved"]
