"""The command line: the commands work, and bad input gets one line, no traceback, nothing written."""

import contextlib
import hashlib
import io
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from reassemble.cli import main


def run(*args):
    """The real console entry point, so what users see is what is tested."""
    proc = subprocess.run([sys.executable, "-m", "reassemble", *map(str, args)],
                          capture_output=True, text=True, timeout=300)
    return proc.returncode, proc.stdout, proc.stderr


def call(*args):
    """The same ``main`` in this process, for checks whose only output is the error line
    (no process start-up each); ``run`` stays the test of what users see."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in args])
        except SystemExit as exc:  # argparse's usage errors
            rc = exc.code
    return rc, out.getvalue(), err.getvalue()


def assert_one_line_error(rc, err, *words):
    assert rc != 0
    assert "Traceback" not in err
    lines = [line for line in err.strip().splitlines() if line.strip()]
    assert len(lines) == 1 or lines[0].startswith("usage:"), err
    for w in words:
        assert w in err, err


@pytest.mark.slow
def test_break_then_eval(tmp_path):
    rc, out, err = run("break", "torus", "--pieces", 3, "--seed", 2, "--out", tmp_path / "p")
    assert rc == 0, err
    assert (tmp_path / "p" / "ground_truth.json").is_file()
    assert len(list((tmp_path / "p" / "fragments").glob("*.ply"))) == 3
    gt = tmp_path / "p" / "ground_truth.json"
    rc, out, err = run("eval", gt, gt, "--out", tmp_path / "score.json")
    assert rc == 0, err
    assert "part accuracy" in out and "1.000" in out
    report = json.loads((tmp_path / "score.json").read_text())
    assert report["alignments"]["anchor_largest"]["summary"]["part_acc_strict"] == 1.0
    # folders are read too: a run's output folder for its transforms.json, a puzzle's for its ground truth
    shutil.copy(gt, tmp_path / "transforms.json")
    rc, out, err = run("eval", tmp_path, tmp_path / "p")
    assert rc == 0, err
    assert "1.000" in out
    rc, out, err = run("eval", tmp_path / "p" / "fragments", tmp_path / "p")
    assert_one_line_error(rc, err, "transforms.json", "no such file")
    rc, out, err = run("eval", tmp_path, tmp_path / "p" / "fragments")
    assert_one_line_error(rc, err, "ground_truth.json", "no such file", "expected a ground_truth.json")


def test_existing_output_is_refused_then_replaced_with_force(tmp_path):
    out = tmp_path / "p"
    assert main(["break", "torus", "--pieces", "2", "--out", str(out)]) == 0
    before = (out / "ground_truth.json").read_bytes()
    rc, _, err = run("break", "torus", "--pieces", 3, "--out", out)
    assert_one_line_error(rc, err, str(out), "--force")
    assert (out / "ground_truth.json").read_bytes() == before
    assert main(["break", "torus", "--pieces", "3", "--out", str(out), "--force"]) == 0
    assert len(list((out / "fragments").glob("*.ply"))) == 3
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "staging folders left behind"


def _open_box(path):
    box = trimesh.creation.box()
    trimesh.Trimesh(box.vertices, box.faces[:-2]).export(path)


def _sheet(path):
    """A wavy open sheet: faces that bound no solid."""
    u, v = np.meshgrid(np.linspace(0, 1, 12), np.linspace(0, 1, 12))
    vertices = np.column_stack([u.ravel(), v.ravel(), 0.1 * np.sin(6 * u.ravel())])
    q = (np.arange(11)[:, None] * 12 + np.arange(11)[None, :]).ravel()
    faces = np.concatenate([np.column_stack([q, q + 1, q + 13]), np.column_stack([q, q + 13, q + 12])])
    trimesh.Trimesh(vertices, faces, process=False).export(path)


@pytest.mark.parametrize(
    "make,words",
    [
        (lambda p: p.write_bytes(b""), ["empty"]),
        (lambda p: p.write_bytes(np.random.default_rng(0).bytes(2000)), ["cannot read"]),
        (_sheet, ["no inside", "open sheet"]),
        (lambda p: p.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                "property float y\nproperty float z\nelement face 1\n"
                                "property list uchar int vertex_indices\nend_header\n"
                                "0 0 0\nnan 1 0\n0 0 1\n3 0 1 2\n"), ["NaN"]),
    ],
    ids=["empty", "random-bytes", "sheet", "nan"],
)
def test_bad_mesh_gets_one_line_and_is_untouched(tmp_path, make, words):
    path = tmp_path / "bad.ply"
    make(path)
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    # through the real entry point once: a sheet reads far enough to warn, if it would
    rc, _, err = (run if "sheet" in words else call)("break", path, "--pieces", 3, "--out", tmp_path / "out")
    assert_one_line_error(rc, err, "bad.ply", *words)
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest
    assert not (tmp_path / "out").exists()


@pytest.mark.slow  # remeshed, broken and written end to end; test_read_any_mesh covers the path quickly
def test_an_open_mesh_is_broken_with_one_warning(tmp_path):
    path = tmp_path / "open.ply"
    _open_box(path)
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    rc, _, err = run("break", path, "--pieces", 2, "--out", tmp_path / "out")
    assert rc == 0
    warnings = [line for line in err.splitlines() if "open.ply" in line]
    assert len(warnings) == 1 and "hole" in warnings[0], err
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest
    assert len(list((tmp_path / "out" / "fragments").glob("*.ply"))) == 2


def test_bad_options(tmp_path):
    rc, _, err = run("break", "torus", "--pieces", 1, "--out", tmp_path / "o")
    assert_one_line_error(rc, err, "--pieces")
    rc, _, err = call("break", "torus", "--pieces", 3, "--roughness", "-2", "--out", tmp_path / "o")
    assert_one_line_error(rc, err, "--roughness")
    rc, _, err = call("break", "no_such_mesh", "--pieces", 3, "--out", tmp_path / "o")
    assert_one_line_error(rc, err, "no_such_mesh", "bundled")
    for bad in ("-0.1", "nan", "wide"):
        rc, _, err = call("run", tmp_path, "--gap", bad, "--out", tmp_path / "o")
        assert_one_line_error(rc, err, "--gap", "auto")
    rc, _, err = call("run", tmp_path, "--thin-walls", "maybe", "--out", tmp_path / "o")
    assert_one_line_error(rc, err, "--thin-walls", "auto")
    for bad in ("0", "2", "all"):
        rc, _, err = call("run", tmp_path, "--fill-holes", bad, "--out", tmp_path / "o")
        assert_one_line_error(rc, err, "--fill-holes", "fraction")
    assert not (tmp_path / "o").exists()


def test_eval_bad_input(tmp_path, puzzle_dir):
    gt = puzzle_dir / "ground_truth.json"
    rc, _, err = call("eval", tmp_path / "missing.json", gt)
    assert_one_line_error(rc, err, "missing.json")
    bad = tmp_path / "transforms.json"
    bad.write_text("{not json")
    rc, _, err = call("eval", bad, gt)
    assert_one_line_error(rc, err, "transforms.json", "JSON")
    bad.write_text(json.dumps({"fragments": {"fragment_00": {"transform": [[1, 0], [0, 1]]}}}))
    rc, _, err = call("eval", bad, gt)
    assert_one_line_error(rc, err, "fragment_00", "rigid")


@pytest.mark.slow
def test_describe_writes_the_documented_arrays(tmp_path):
    out = tmp_path / "torus.npz"
    rc, stdout, err = run("describe", "torus", "--radii", "0.05,0.1", "--relative", "--out", out)
    assert rc == 0, err
    with np.load(out) as z:
        n = len(z["vertices"])
        assert z["radii"].shape == (2,)
        for key in ("V", "D2", "H", "H_rob", "K2"):
            assert z[key].shape == (n, 2) and np.isfinite(z[key]).all()
    rc, _, err = run("describe", "torus", "--radii", "0.05", "--relative", "--out", out)
    assert_one_line_error(rc, err, "exists", "--force")
    rc, _, err = run("describe", "torus", "--radii", "0.05", "--relative", "--out", out, "--force",
                     "--principal", "--no-d2")
    assert rc == 0, err
    with np.load(out) as z:
        n = len(z["vertices"])
        assert z["normal"].shape == (n, 1, 3) and z["dir1"].shape == (n, 1, 3)
        assert np.allclose(np.linalg.norm(z["normal"], axis=-1), 1.0)
        assert (z["k1"] >= z["k2"]).all() and np.isnan(z["D2"]).all()


def test_describe_bad_input(tmp_path):
    _sheet(tmp_path / "sheet.stl")
    rc, _, err = call("describe", tmp_path / "sheet.stl", "--radii", "0.1", "--out", tmp_path / "o.npz")
    assert_one_line_error(rc, err, "sheet.stl", "no inside")
    rc, _, err = call("describe", "torus", "--radii", "-1", "--out", tmp_path / "o.npz")
    assert_one_line_error(rc, err, "positive")
    rc, _, err = call("describe", "torus", "--radii", "1e-4", "--out", tmp_path / "o.npz", "--max-memory", "1M")
    assert_one_line_error(rc, err, "--max-memory")
    assert not (tmp_path / "o.npz").exists()
    _open_box(tmp_path / "open.stl")  # an open scan: described as it is, its hole bridged
    rc, _, err = run("describe", tmp_path / "open.stl", "--radii", "0.1", "--relative", "--out", tmp_path / "o.npz")
    assert rc == 0 and "hole" in err, err
    with np.load(tmp_path / "o.npz") as z:
        assert np.isfinite(z["V"]).all()


@pytest.mark.slow
def test_match_writes_pairs_and_debug_files(puzzle_dir, tmp_path):
    frag_dir = puzzle_dir / "fragments"
    before = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in frag_dir.iterdir()}
    # a stray non-mesh and an unreadable mesh among good ones: skipped with a warning
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    for p in sorted(frag_dir.glob("*.ply"))[:2]:
        (mixed / p.name).write_bytes(p.read_bytes())
    (mixed / "notes.txt").write_text("not a mesh")
    (mixed / "broken.ply").write_bytes(b"\x00garbage")
    rc, out, err = run("match", mixed, "--out", tmp_path / "m", "--debug-files", "--quiet")
    assert rc == 0, err
    assert "broken.ply" in err and "Traceback" not in err
    pairs = json.loads((tmp_path / "m" / "pairs.json").read_text())
    assert pairs["convention"] == "T_target_source" and len(pairs["pairs"]) == 1
    cands = pairs["pairs"][0]["candidates"]
    assert cands and all(a["score"] >= b["score"] for a, b in zip(cands, cands[1:]))
    labels = trimesh.load(tmp_path / "m" / "labels" / "fragment_00.ply", process=False)
    colors = np.asarray(labels.visual.vertex_colors)[:, :3]
    assert {tuple(c) for c in np.unique(colors, axis=0)} <= {(214, 69, 50), (190, 190, 190)}
    assert len(np.unique(colors, axis=0)) == 2
    assert (tmp_path / "m" / "config.json").is_file()
    rc, _, err = run("match", mixed, "--out", tmp_path / "m", "--quiet")
    assert_one_line_error(rc, err, "exists", "--force")
    assert before == {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in frag_dir.iterdir()}


@pytest.mark.parametrize("command", ["match", "run"])
def test_folder_commands_bad_input(tmp_path, command):
    empty = tmp_path / "empty"
    empty.mkdir()
    rc, _, err = call(command, empty, "--out", tmp_path / "o")
    assert_one_line_error(rc, err, "no mesh files")
    rc, _, err = call(command, tmp_path / "missing", "--out", tmp_path / "o")
    assert_one_line_error(rc, err, "no such file")
    one = tmp_path / "one"
    one.mkdir()
    trimesh.creation.box().export(one / "a.ply")
    rc, _, err = call(command, one, "--out", tmp_path / "o")
    assert_one_line_error(rc, err, "at least two")
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_run_and_demo(cli_run, puzzle_dir, tmp_path):
    folder, out = cli_run  # `reassemble run FRAGMENTS --out FOLDER --seed 0 --jobs 1 --quiet`
    assert "4 of 4 fragments placed" in out
    assert {"transforms.json", "assembled.glb", "assembled.ply", "report.json"} <= {p.name for p in folder.iterdir()}
    rc, out, err = run("eval", folder / "transforms.json", puzzle_dir / "ground_truth.json")
    assert rc == 0, err
    rc, out, err = run("demo", "--mesh", "spot_low_resolution", "--pieces", 2, "--out", tmp_path / "d", "--quiet")
    assert rc == 0, err
    assert "2 of 2 fragments placed" in out and "solved" in out
    score = json.loads((tmp_path / "d" / "result" / "score.json").read_text())
    assert score["alignments"]["anchor_largest"]["summary"]["solved"]
    rc, _, err = run("demo", "--mesh", "spot_low_resolution", "--pieces", 2, "--out", tmp_path / "d", "--quiet")
    assert_one_line_error(rc, err, "exists", "--force")


def test_run_bad_file_among_too_few(tmp_path):
    one = tmp_path / "one"
    one.mkdir()
    trimesh.creation.box().export(one / "a.ply")
    (one / "b.ply").write_bytes(b"ply\nrandom bytes")
    rc, _, err = run("run", one, "--out", tmp_path / "o")
    # the unreadable file is warned about, then the one-line error
    assert rc == 2 and "Traceback" not in err and "b.ply" in err
    assert err.strip().splitlines()[-1].startswith("reassemble: error:") and "at least two" in err
    assert not (tmp_path / "o").exists()
    rc, _, err = run("run", one, "--out", tmp_path / "o", "--jobs", "-1")
    assert rc == 2 and "Traceback" not in err
