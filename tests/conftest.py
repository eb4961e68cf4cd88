import os
import subprocess
import sys

import numpy as np
import pytest

from reassemble.allocator import retain_freed_memory
from reassemble.pipeline import break_to_folder, prepare_fragments, read_puzzle, run_to_folder
from reassemble.synth import BreakParams

retain_freed_memory()  # as `reassemble` does: the in-process runs of every worker fault their grids in once


def pytest_xdist_auto_num_workers(config):
    """``-n auto`` (pyproject.toml): one worker per usable core, at most four (each
    end-to-end run holds a few hundred MB, and the session's shared runs are made once per
    worker)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(4, cores))


class Puzzles:
    """Puzzles of bundled meshes and their ``reassemble run`` (seed 0), each made at most once
    per session, on first use; tests copy what they change. Several tests (and the smoke-set
    cases of the same puzzle) share one run: an end-to-end run is the suite's costly part."""

    def __init__(self, root):
        self.root = root
        self._puzzles, self._runs = {}, {}

    def puzzle(self, mesh: str, pieces: int, seed: int):
        """The folder of ``reassemble break MESH --pieces PIECES --seed SEED``."""
        key = (mesh, pieces, seed)
        if key not in self._puzzles:
            out = self.root / f"{mesh}_{pieces:02d}p_s{seed}"
            break_to_folder(mesh, out, params=BreakParams(pieces=pieces), seed=seed)
            self._puzzles[key] = out
        return self._puzzles[key]

    def run(self, mesh: str, pieces: int, seed: int):
        """The output folder of ``run_to_folder`` on that puzzle's fragments, seed 0."""
        key = (mesh, pieces, seed)
        if key not in self._runs:
            out = self.root / f"{mesh}_{pieces:02d}p_s{seed}_run"
            run_to_folder([self.puzzle(*key) / "fragments"], out, seed=0)
            self._runs[key] = out
        return self._runs[key]

    def share_run(self, mesh: str, pieces: int, seed: int, out):
        """Record ``out`` as that puzzle's run, made elsewhere with the same options."""
        self._runs[(mesh, pieces, seed)] = out


@pytest.fixture(scope="session")
def puzzles(tmp_path_factory):
    return Puzzles(tmp_path_factory.mktemp("puzzles"))


COW = ("spot_low_resolution", 4, 1)  # the suite's puzzle (a smoke-set case too)
SMALL_COW = ("spot_low_resolution", 2, 0)  # the smallest smoke-set case: two fragments
TORUS3 = ("torus", 3, 0)  # a smoke-set case: three fragments, three pairs

# Session fixtures are made once per xdist worker, and an end-to-end run is the suite's
# costly part: the tests that share one run are sent to one worker (--dist loadgroup,
# pyproject.toml), so it is made once. Tests that ask ``puzzles.run`` for a shared run
# carry ``@shared_run(KEY)``; those that use the fixtures below are grouped on collection.
def _group(key) -> str:
    mesh, pieces, seed = key
    return f"{mesh}_{pieces:02d}p_s{seed}"


_FIXTURE_GROUPS = {"cli_run": _group(COW), "run_dir": _group(COW), "prepared": _group(COW) + "_prepared"}


def shared_run(key) -> pytest.MarkDecorator:
    """Mark a test that uses ``puzzles.run(*key)``: it runs on the worker that makes that run."""
    return pytest.mark.xdist_group(_group(key))


@pytest.hookimpl(tryfirst=True)  # before xdist reads the groups
def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.get_closest_marker("xdist_group") is None:
            group = next((g for name, g in _FIXTURE_GROUPS.items() if name in item.fixturenames), None)
            if group:
                item.add_marker(pytest.mark.xdist_group(group))
    if os.environ.get("PYTEST_XDIST_WORKER"):
        # the long tests first, the quick ones after, to fill in: the workers finish together
        items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.fixture(scope="session")
def puzzle_dir(puzzles):
    """A 4-piece rough-cut puzzle of the low-resolution cow, built once per session."""
    return puzzles.puzzle(*COW)


@pytest.fixture(scope="session")
def cli_run(puzzle_dir, puzzles):
    """`reassemble run` on the 4-piece cow through the console entry point, once per session:
    (output folder, printed output). Tests copy the folder before changing it."""
    out = puzzles.root / "cow_cli_run"
    proc = subprocess.run([sys.executable, "-m", "reassemble", "run", str(puzzle_dir / "fragments"), "--out", str(out),
                           "--seed", "0", "--jobs", "1", "--quiet"], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    puzzles.share_run(*COW, out)  # the same run as run_to_folder(seed=0): the smoke-set case uses it too
    return out, proc.stdout


@pytest.fixture(scope="session")
def run_dir(cli_run):
    """`reassemble run` on the 4-piece cow, once per session (tests copy it before changing it)."""
    return cli_run[0]


@pytest.fixture(scope="session")
def puzzle(puzzle_dir):
    return read_puzzle(puzzle_dir / "ground_truth.json")


@pytest.fixture(scope="session")
def prepared(puzzle):
    """prepare_fragments (seed 0) of the 4-piece cow: (fragments, reference size). Not to be changed."""
    meshes = {n: (m.vertices, m.faces) for n, m in puzzle.meshes.items()}
    return prepare_fragments(meshes, seed=0)


def labelled(vertices, faces, fracture):
    """A Segmentation with the given (f,) fracture labels, one patch, one region (for the mates' tests)."""
    from reassemble.geometry import face_areas
    from reassemble.segmentation import Segmentation

    area = face_areas(vertices, faces)
    return Segmentation(fracture.copy(), fracture.astype(float), np.zeros(len(faces), int), np.where(fracture, 0, -1),
                        float(area[fracture].sum()), float(area.sum()))


def tree_digest(root):
    """{relative path: bytes} of every file below root."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def assert_same_run(a, b) -> None:
    """Two run folders hold the same files, byte for byte but for report.json's timings."""
    import json

    a, b = tree_digest(a), tree_digest(b)
    assert sorted(a) == sorted(b)
    for k in a:
        if k == "report.json":  # holds timings
            ra, rb = json.loads(a[k]), json.loads(b[k])
            ra["summary"].pop("timings_s"), rb["summary"].pop("timings_s")
            assert ra == rb
        else:
            assert a[k] == b[k], k


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
