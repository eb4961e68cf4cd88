"""Fuzzing, for a bounded time: the mesh loader and the command line never fail with
anything but a one-line ReassembleError / usage message."""

import io
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from reassemble.cli import main
from reassemble.errors import ReassembleError
from reassemble.files import load_mesh

SETTINGS = settings(max_examples=150, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def _valid(suffix: str) -> bytes:
    box = trimesh.creation.box()
    return trimesh.Trimesh(box.vertices, box.faces).export(file_type=suffix.lstrip("."), encoding="ascii") \
        if suffix == ".ply" else trimesh.Trimesh(box.vertices, box.faces).export(file_type=suffix.lstrip("."))


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".off", ".stl"])
@SETTINGS
@given(data=st.data())
def test_loader_survives_mutated_files(tmp_path_factory, suffix, data):
    valid = _valid(suffix)
    valid = valid.encode() if isinstance(valid, str) else valid
    kind = data.draw(st.sampled_from(["flip", "truncate", "splice", "random"]))
    b = bytearray(valid)
    if kind == "flip":
        for i in data.draw(st.lists(st.integers(0, len(b) - 1), min_size=1, max_size=20)):
            b[i] = data.draw(st.integers(0, 255))
    elif kind == "truncate":
        b = b[: data.draw(st.integers(0, len(b)))]
    elif kind == "splice":
        at = data.draw(st.integers(0, len(b)))
        b = b[:at] + data.draw(st.binary(max_size=64)) + b[at:]
    else:
        b = bytearray(data.draw(st.binary(max_size=2000)))
    path = tmp_path_factory.mktemp("fuzz") / f"m{suffix}"
    path.write_bytes(bytes(b))
    try:
        m = load_mesh(path)
    except ReassembleError as exc:
        assert str(path) in str(exc) and "\n" not in str(exc)
    else:
        assert m.faces.ndim == 2 and m.faces.shape[1] == 3 and np.all(np.isfinite(m.vertices))
    assert path.read_bytes() == bytes(b)


WORDS = ["run", "match", "view", "eval", "describe", "break", "--out", "--force", "--seed", "--jobs", "--pieces",
         "--radii", "--max-memory", "--truth", "--radius", "--size", "-1", "0", "x", "1e400", "nan", "3", "10x",
         "0,0", "G", "--noise", "--quiet"]


@SETTINGS
@given(argv=st.lists(st.one_of(st.sampled_from(WORDS), st.sampled_from(["BAD", "MISSING", "FILE"])), max_size=8))
def test_cli_survives_random_arguments(tmp_path_factory, argv):
    root = tmp_path_factory.mktemp("cli")
    (root / "bad.ply").write_bytes(b"\x00garbage")
    (root / "file.txt").write_text("x")
    paths = {"BAD": str(root / "bad.ply"), "MISSING": str(root / "missing"), "FILE": str(root / "file.txt")}
    argv = [paths.get(a, a) for a in argv]
    if argv and argv[0] == "break":  # a valid break of a bundled mesh is real work, not fuzz
        argv = argv + ["--pieces", "1"]
    err, out = io.StringIO(), io.StringIO()
    with redirect_stderr(err), redirect_stdout(out):
        try:
            rc = main(argv)
        except SystemExit as exc:  # argparse: usage errors and --help
            rc = exc.code
    text = err.getvalue()
    assert "Traceback" not in text and "internal error" not in text, (argv, text)
    assert rc in (0, 2), (argv, rc, text)
