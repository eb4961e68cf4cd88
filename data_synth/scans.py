"""Open scans from a puzzle: every fragment with a disc of its original surface cut away."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def punch_holes(puzzle_dir: str | Path, out: str | Path, *, radius: float, seed: int) -> None:
    """Write every fragment of the puzzle at ``puzzle_dir`` to ``out`` (made) with one hole.

    The hole removes the faces within ``radius`` (a fraction of the object's diagonal) of a
    seeded random face centre on the fragment's original (not fracture) surface, as a scan
    that missed a patch would.
    """
    from reassemble.files import write_ply
    from reassemble.pipeline import read_puzzle

    puzzle = read_puzzle(Path(puzzle_dir) / "ground_truth.json")
    rng = np.random.default_rng(seed)
    diag = float(puzzle.ground_truth["object"]["diagonal"])
    out = Path(out)
    out.mkdir()
    for name, m in sorted(puzzle.meshes.items()):
        centres = m.vertices[m.faces].mean(axis=1)
        at = centres[rng.choice(np.flatnonzero(puzzle.labels[name] == 0))]
        keep = np.linalg.norm(centres - at, axis=1) > radius * diag
        used, faces = np.unique(m.faces[keep], return_inverse=True)
        write_ply(out / f"{name}.ply", m.vertices[used], faces.reshape(-1, 3))
