import numpy as np
import pytest

from reassemble.pipeline import break_to_folder, read_puzzle, run_to_folder
from reassemble.synth import BreakParams


@pytest.fixture(scope="session")
def puzzle_dir(tmp_path_factory):
    """A 4-piece rough-cut puzzle of the low-resolution cow, built once per session."""
    out = tmp_path_factory.mktemp("puzzles") / "spot4"
    break_to_folder("spot_low_resolution", out, params=BreakParams(pieces=4), seed=1)
    return out


@pytest.fixture(scope="session")
def run_dir(puzzle_dir, tmp_path_factory):
    """`reassemble run` on the 4-piece cow, once per session (tests copy it before changing it)."""
    out = tmp_path_factory.mktemp("run") / "out"
    run_to_folder([puzzle_dir / "fragments"], out, seed=0)
    return out


@pytest.fixture(scope="session")
def puzzle(puzzle_dir):
    return read_puzzle(puzzle_dir / "ground_truth.json")


def tree_digest(root):
    """{relative path: bytes} of every file below root."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
