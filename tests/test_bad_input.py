"""The bad-input corpus of `reassemble run`: every case ends in one line of error or a
documented graceful result, never a traceback, and the input files stay byte-identical."""

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import trimesh

from .conftest import TORUS3, assert_same_run, shared_run, tree_digest
from .test_cli import assert_one_line_error, run


def _digests(folder):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


NAN_PLY = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
           "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\nnan 1 0\n0 0 1\n3 0 1 2\n")


@pytest.fixture(scope="module")
def mixed(puzzle_dir, tmp_path_factory):
    """The 4-piece cow with every kind of bad or odd file among its fragments, and its run."""
    root = tmp_path_factory.mktemp("mixed")
    folder = root / "in"
    folder.mkdir()
    src = puzzle_dir / "fragments"
    load = lambda name: trimesh.load(src / f"{name}.ply", process=False)  # noqa: E731
    shutil.copy(src / "fragment_00.ply", folder / "fragment_00.ply")
    shutil.copy(src / "fragment_00.ply", folder / "twin.ply")  # an identical duplicate
    # zero-area and duplicate faces, and a triangle soup (no shared vertices): cleaned on loading
    m = load("fragment_01")
    tri = m.vertices[m.faces].reshape(-1, 3)
    soup = np.arange(len(tri)).reshape(-1, 3)
    faces = np.vstack([soup, soup[:5], [[soup[0, 0], soup[0, 0], soup[0, 1]]]])
    trimesh.Trimesh(tri, faces, process=False).export(folder / "fragment_01.ply")
    # two fragments saved in one file, plus a speck of scan debris
    a, b = load("fragment_02"), load("fragment_03")
    speck = trimesh.creation.icosphere(subdivisions=1, radius=1e-3 * a.scale)
    speck.apply_translation(a.bounds[1] + 0.05 * a.scale)
    trimesh.util.concatenate([a, b, speck]).export(folder / "pair.ply")
    (folder / "empty.ply").write_bytes(b"")
    (folder / "random.ply").write_bytes(np.random.default_rng(0).bytes(3000))
    (folder / "nan.ply").write_text(NAN_PLY)
    box = trimesh.creation.box()
    trimesh.Trimesh(box.vertices, box.faces[:2]).export(folder / "open.stl")  # one flat sheet: no inside
    (folder / "notes.txt").write_text("not a mesh")
    before = _digests(folder)
    rc, out, err = run("run", folder, "--out", root / "out", "--quiet", "--jobs", 1, "--split-bodies")
    return folder, root / "out", before, rc, out, err


@pytest.mark.slow
def test_mixed_folder_is_handled_as_documented(mixed):
    folder, out, before, rc, stdout, err = mixed
    assert rc == 0, err
    assert "Traceback" not in err
    report = json.loads((out / "report.json").read_text())
    warnings = report["warnings"]
    expect = {"empty.ply": "empty", "random.ply": "cannot read", "nan.ply": "NaN", "open.stl": "has no inside",
              "twin.ply": "skipped", "pair.ply": "2 separate bodies"}
    for name, words in expect.items():
        assert any(name in w and words in w for w in warnings), (name, warnings)
    assert any("pair.ply" in w and "debris" in w for w in warnings)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == len(warnings)  # one line each, nothing else
    assert not any("notes.txt" in w for w in warnings)  # not a mesh suffix: not ours to judge
    frags = report["fragments"]
    assert set(frags) == {"fragment_00", "fragment_01", "pair.1", "pair.2"}  # the twin is skipped
    for name, f in frags.items():
        assert f["placed"] and f["confidence"] > 0.5, (name, f)
    assert _digests(folder) == before


def test_memory_budget_is_refused_naming_the_option(puzzle_dir, tmp_path):
    before = _digests(puzzle_dir / "fragments")
    rc, _, err = run("run", puzzle_dir / "fragments", "--out", tmp_path / "o", "--max-memory", "1M", "--jobs", 1,
                      "--quiet")
    assert_one_line_error(rc, err, "--max-memory", "limit 1 MB")
    assert not (tmp_path / "o").exists() and list(tmp_path.iterdir()) == []
    assert _digests(puzzle_dir / "fragments") == before


def test_unwritable_output(puzzle_dir, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    t = time.perf_counter()
    rc, _, err = run("run", puzzle_dir / "fragments", "--out", blocker / "out", "--jobs", 1)
    assert_one_line_error(rc, err, "out", "cannot create output folder")
    assert time.perf_counter() - t < 20  # refused before the work, not after
    assert blocker.read_text() == "x"


@pytest.mark.slow
@shared_run(TORUS3)
def test_killed_run_leaves_no_output_and_a_rerun_gives_the_same_files(puzzles, tmp_path):
    """A run of the 3-piece torus killed mid-way leaves nothing; run again, in two processes
    (--jobs 2), it writes what the smoke-set run of it (one process) wrote, byte for byte but
    for the timings: the result depends neither on the processes nor on an earlier run's leftovers."""
    puzzle_dir, run_dir = puzzles.puzzle(*TORUS3), puzzles.run(*TORUS3)
    before = _digests(puzzle_dir / "fragments")
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "reassemble", "run", str(puzzle_dir / "fragments"), "--out", str(out), "--quiet",
           "--jobs", "1"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    time.sleep(4.0)  # mid-run: descriptors or pairs
    assert proc.poll() is None
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not out.exists()
    # what a run killed while writing leaves: its hidden staging folder, named by its (dead) process
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".out.{dead.pid}.abcd1234.partial"
    stale.mkdir()
    (stale / "pairs.json").write_text("{")
    rc, _, err = run("run", puzzle_dir / "fragments", "--out", out, "--quiet", "--jobs", 2, "--seed", 0)
    assert rc == 0, err
    assert not stale.exists() and not list(tmp_path.glob(".out.*"))
    assert _digests(puzzle_dir / "fragments") == before
    assert {"transforms.json", "report.json", "pairs.json", "assembled.glb", "assembled.ply", "analysis.npz",
            "config.json"} <= set(tree_digest(run_dir))
    assert_same_run(run_dir, out)
